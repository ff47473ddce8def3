"""Residual structure no effect explains: one small class per shape.

Each shape has a ``kind``, ``extra`` parameters, ``trials`` (how many distinct shapes its
search tries, counted in the Bonferroni correction), :meth:`basis` giving its extra linear
columns and wavelength (None when the case cannot show it), and :meth:`describe`, the
evidence line saying what varies and by how much.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar

from ..effects import Effect, Parameter
from .judge import Test, drift_basis
from ..iso230 import target_clusters
from .spectrum import amplitude_spectrum, resolvable_band_per_mm

MAX_TREND_DEGREE = 3


@dataclass
class Structure:
    """A structure found in the residual, with its test."""

    kind: str
    wavelength_mm: float | None
    amplitude_um: float
    test: Test
    evidence: str
    fitted_um: np.ndarray = field(repr=False)
    basis: np.ndarray | None = field(default=None, repr=False)

    def to_json(self):
        return {"kind": self.kind, "wavelength_mm": self.wavelength_mm,
                "amplitude_um": self.amplitude_um, "evidence": self.evidence,
                **self.test.to_json()}


@dataclass
class Context:
    """What the shapes look at: the case's samples, layout and catalog wavelengths."""

    position_mm: np.ndarray
    direction: np.ndarray
    bidirectional: bool
    layout: object
    marks: dict


def least_squares_fit(residual_um, basis):
    """Projection of the residual on the columns of ``basis``."""
    coefficients = np.linalg.lstsq(basis, residual_um, rcond=None)[0]
    return basis @ coefficients


def _normalised(values):
    span = np.ptp(values)
    return (values - values.mean()) / (span if span > 0 else 1.0)


class Periodic:
    """A sinusoid of free wavelength along the travel (cos, sin and the wavelength)."""

    kind = "periodic"
    extra = 3

    def trials(self, context):
        """Independent frequencies in the resolvable band (Rayleigh spacing 1/span)."""
        centres, _ = target_clusters(context.position_mm)
        if centres.size < 8:
            return 0
        low, high = resolvable_band_per_mm(centres)
        return max(int((high - low) * np.ptp(centres)), 1)

    def basis(self, context, residual_um):
        spectrum = amplitude_spectrum(context.position_mm, residual_um)
        if spectrum is None or spectrum.amplitude_um.size == 0:
            return None, None
        position_mm = context.position_mm
        peak = 1.0 / spectrum.wavelength_mm[int(np.argmax(spectrum.amplitude_um))]
        centres, _ = target_clusters(position_mm)
        step = 1.0 / (5 * np.ptp(centres))
        best = minimize_scalar(
            lambda f: _rss(residual_um - least_squares_fit(residual_um, sinusoid(position_mm, f))),
            bounds=(max(peak - step, step / 2), peak + step), method="bounded",
            options={"xatol": step * 1e-4})
        return sinusoid(position_mm, best.x), float(1.0 / best.x)

    def describe(self, context, fitted_um, wavelength_mm):
        amplitude = np.ptp(fitted_um) / 2
        return (f"peak at {wavelength_mm:.4g} mm, amplitude {amplitude:.3g} µm; "
                f"{_compare_to_marks(wavelength_mm, context.marks)}")


class Direction:
    """A reversal that changes along the travel (friction or stiffness, not a constant B)."""

    kind = "direction"
    extra = 2

    def trials(self, context):
        return 1 if context.bidirectional else 0

    def basis(self, context, residual_um):
        scaled = _normalised(context.position_mm)
        return np.column_stack((context.direction, context.direction * scaled)), None

    def describe(self, context, fitted_um, wavelength_mm=None):
        position_mm, direction = context.position_mm, context.direction
        ends = [position_mm.min(), position_mm.max()]
        reversal = []
        for end in ends:
            near = np.abs(position_mm - end) <= 1e-9 + 0.05 * np.ptp(position_mm)
            reversal.append(np.mean(fitted_um[near & (direction > 0)])
                            - np.mean(fitted_um[near & (direction < 0)]))
        return (f"the reversal changes by {reversal[1] - reversal[0]:+.3g} µm along the travel "
                f"(left of the model: {reversal[0]:+.3g} µm at {ends[0]:g} mm, "
                f"{reversal[1]:+.3g} µm at {ends[1]:g} mm): friction or stiffness, not a "
                "constant backlash")


class Drift:
    """A drift along the test's clock (time, else run order): linear and quadratic."""

    kind = "drift"
    extra = 2

    def trials(self, context):
        return 1 if context.layout.clock_varies_within_groups else 0

    def basis(self, context, residual_um=None):
        return drift_basis(context.layout.clock), None

    def describe(self, context, fitted_um, wavelength_mm=None):
        clock, unit = context.layout.clock, context.layout.clock_unit
        first, last = np.argmin(clock), np.argmax(clock)
        change = float(fitted_um[last] - fitted_um[first])
        span = float(np.ptp(clock))
        per = "per hour" if unit == "h" else "per run"
        over = f"{span:.2g} h" if unit == "h" else f"{span:.2g} runs"
        return (f"the error drifts {change:+.3g} µm over the test ({over}), {change / span:+.3g} "
                f"µm {per} on average, the same at every target; a drift, not an effect")


class Trend:
    """A straight line, bow or S-shape along the travel."""

    kind = "trend"
    extra = MAX_TREND_DEGREE

    def trials(self, context):
        return MAX_TREND_DEGREE if target_clusters(context.position_mm)[0].size >= 4 else 0

    def basis(self, context, residual_um):
        return np.vander(_normalised(context.position_mm), MAX_TREND_DEGREE + 1), None

    def describe(self, context, fitted_um, wavelength_mm=None):
        return (f"the residual follows a polynomial of degree up to {MAX_TREND_DEGREE} along "
                f"the travel, {np.ptp(fitted_um):.3g} µm peak to valley")


SHAPES = (Periodic, Direction, Trend)  # a drift is a nuisance of the decision


def sinusoid(position_mm, frequency_per_mm):
    """Basis cos, sin, 1 at one spatial frequency (1/mm)."""
    phase = 2 * np.pi * frequency_per_mm * position_mm
    return np.column_stack((np.cos(phase), np.sin(phase), np.ones_like(phase)))


def _compare_to_marks(wavelength_mm, marks):
    for label, mark_mm in marks.items():
        ratio = wavelength_mm / mark_mm
        for harmonic in (1, 2, 3):
            if abs(ratio * harmonic - 1) < 0.02:
                which = "the wavelength" if harmonic == 1 else f"harmonic {harmonic}"
                return (f"{which} of {label} ({mark_mm:.4g} mm), but that effect's shape "
                        "does not fit it")
    known = ", ".join(f"{label} {mm:.4g} mm" for label, mm in marks.items()) or "none"
    return f"matches no catalog wavelength ({known})"


def _rss(values):
    return float(values @ values)


class StructureEffect(Effect):
    """A found structure as a temporary linear effect, refitted with the model."""

    def __init__(self, name, basis):
        self.name, self.basis = name, basis
        self.parameters = tuple(Parameter(f"c{i}_um", "um", -1e6, 1e6)
                                for i in range(basis.shape[1]))
        self.linear = self.parameter_names

    def prepare(self, case):
        return lambda v: self.basis @ np.array([v[p.name] for p in self.parameters])

    def guess(self, case, residual_um):
        coefficients = np.linalg.lstsq(self.basis, residual_um, rcond=None)[0]
        return {p.name: float(c) for p, c in zip(self.parameters, coefficients)}
