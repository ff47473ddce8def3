"""Positioning deviations at targets (positioning.csv, laser-interferometer style).

The model's effects add errors at each target (:attr:`feedaxis.effects.Effect.additive`).
Samples repeated at one target and approach direction give the pure error; a dense scan
without repeats is judged against the residual mean square. Structure is searched along
the travel: a sinusoid of free wavelength, a reversal changing along the travel, a
polynomial trend; a drift along the test's clock is a nuisance of every fit; what is left
is tested for lack of fit (repeats) or serial correlation (no repeats). ``compare`` gives
the ISO 230-2 figures of the measurement and of the residual.
"""
from __future__ import annotations

from dataclasses import replace
from functools import cached_property

import numpy as np
from scipy.optimize import minimize_scalar

from ..iso230 import FIGURE_NAMES, SAME_TARGET_MM, iso230_figures, target_clusters
from ..stats import judge
from ..stats.judge import Layout, drift_basis
from ..stats.noise import PureError, ResidualMeanSquare
from ..stats.spectrum import amplitude_spectrum, marked_wavelengths, resolvable_band_per_mm
from .base import Measurement, Shape, Trial

MAX_TREND_DEGREE = 3
MAX_PHASE_CONCENTRATION = 0.9
SAMPLE_COLUMNS = ("target_mm", "error_um", "direction", "run", "time_s", "ambient_C")


class Positioning(Measurement):
    """The positioning samples of a case."""

    kind = "positioning"
    file = "positioning.csv"
    location_key = "wavelength_mm"
    location_unit = "mm"
    coordinate_label = "target position (mm)"
    reference_label = "measured"
    stages = ("drift", "effects", "structures", "lack of fit")

    def __init__(self, case):
        super().__init__(case)
        self.samples = case.positioning
        self.measured_um = np.asarray(self.samples.error_um, dtype=float)
        self.position_mm = self.coordinate = self.samples.target_mm
        self.direction = self.samples.direction
        self.bidirectional = self.samples.bidirectional
        self.marks = {}

    @cached_property
    def layout(self):
        """Repeat groups and the test's clock."""
        return Layout.of(self.samples)

    def describe(self):
        return (f"{self.size} samples at {target_clusters(self.position_mm)[0].size} targets, "
                f"{self.position_mm.min():g} to {self.position_mm.max():g} mm")

    def unresolvable(self, effect):
        """Why the targets cannot resolve a periodic effect's wavelength (None when they can)."""
        try:
            wavelength_mm = effect.wavelength_mm(self.case.axis)
        except KeyError:
            return None
        if not wavelength_mm:
            return None
        centres_mm, _ = target_clusters(self.position_mm)
        if centres_mm.size < 3:
            return f"its {wavelength_mm:.4g} mm wavelength needs at least 3 targets"
        concentration = abs(np.mean(np.exp(2j * np.pi * centres_mm / wavelength_mm)))
        if concentration > MAX_PHASE_CONCENTRATION:
            return (f"all targets sit at nearly the same phase of its {wavelength_mm:.4g} mm "
                    f"wavelength (phase concentration {concentration:.2f})")
        spacing_mm = float(np.median(np.diff(centres_mm)))
        if wavelength_mm < 2 * spacing_mm:
            return (f"its {wavelength_mm:.4g} mm wavelength is shorter than twice the median "
                    f"target spacing ({spacing_mm:.4g} mm): the targets alias it")
        return None

    def degenerate(self):
        if np.ptp(self.position_mm) < SAME_TARGET_MM and self.samples.time_s is None:
            return (f"every sample is at the one target {self.position_mm[0]:g} mm (within "
                    f"{SAME_TARGET_MM * 1e3:g} µm): a positioning test needs at least "
                    "two targets")
        return None

    @cached_property
    def noise(self):
        if self.layout.has_repeats:
            return PureError(self.layout)
        return ResidualMeanSquare(np.lexsort((self.position_mm, self._run_or_time())))

    def _run_or_time(self):
        if self.samples.time_s is not None:
            return self.samples.time_s
        return self.samples.run if self.samples.run is not None else np.zeros(self.size)

    def outliers(self, residual_um):
        return judge.outlier_rows(self.layout, self.position_mm, residual_um)

    def subset(self, keep):
        kept = {name: None if getattr(self.samples, name) is None else
                getattr(self.samples, name)[keep] for name in SAMPLE_COLUMNS}
        return Positioning(replace(self.case, positioning=replace(self.samples, **kept)))

    def nuisances(self):
        """A drift along the clock, whenever repeats show one can be told from the targets:
        in a bidirectional test + and - runs alternate, so an unmodelled drift would alias
        into the reversal."""
        drift = Drift()
        if not drift.trials(self):
            return []
        return [("drift", drift, drift.trial(self, None).basis)]

    def shapes(self, effects):
        self.marks = marked_wavelengths(self.case.axis, effects)
        return (Periodic(), Direction(), Trend())

    def irregular(self, current):
        """An irregular error along the travel: lack of fit beyond the noise (repeats, the
        group means against the pure error) or serial correlation along the travel."""
        residual = current.residual_um
        layout = self.layout
        n_within = sum(len(e.parameters) for e in current.model.effects if e.name == "drift")
        n_between = current.statistics.n_free - n_within
        if layout.has_repeats and layout.n_groups > n_between + 1:
            test = judge.lack_of_fit_test(layout, residual, n_between, n_within)
            means = layout.group_means(residual)
            what = (f"the mean error at each target scatters {np.std(means):.3g} µm beyond the "
                    f"repeatability")
        elif not layout.has_repeats and residual.size >= 30:
            test = judge.serial_correlation_test(self.position_mm, residual)
            means = residual
            what = (f"residual RMS {np.sqrt(np.mean(residual**2)):.3g} µm, neighbouring "
                    "samples alike")
        else:
            return None
        return ("irregular", test, means,
                f"{what}, irregularly along the travel: a lead-error table would capture it")

    def figures(self, result):
        """ISO 230-2 figures of the measurement and of the residual after the model, side
        by side; ``explained`` = 1 - residual / measured, the share the model explains."""
        samples = self.samples
        measured = iso230_figures(samples.target_mm, result.measured_um, samples.direction)
        residual = iso230_figures(samples.target_mm, result.residual_um, samples.direction)
        figures = {}
        for key, name in FIGURE_NAMES.items():
            if key in measured:
                explained = 1 - residual[key] / measured[key] if measured[key] else None
                figures[key] = {"name": name, "measured_um": measured[key],
                                "residual_um": residual[key], "explained": explained}
        return {"case": str(self.case.folder), "kind": self.kind,
                "effects": list(result.model.names), "targets": measured["targets"],
                "runs_up": measured.get("runs_up", 0), "runs_down": measured.get("runs_down", 0),
                "bidirectional": samples.bidirectional,
                "rms_measured_um": result.statistics.rms_before_um,
                "rms_residual_um": result.statistics.rms_um, "figures": figures}


def least_squares_fit(residual_um, basis):
    """Projection of the residual on the columns of ``basis``."""
    coefficients = np.linalg.lstsq(basis, residual_um, rcond=None)[0]
    return basis @ coefficients


def _normalised(values):
    span = np.ptp(values)
    return (values - values.mean()) / (span if span > 0 else 1.0)


def sinusoid(position_mm, frequency_per_mm):
    """Basis cos, sin, 1 at one spatial frequency (1/mm)."""
    phase = 2 * np.pi * frequency_per_mm * position_mm
    return np.column_stack((np.cos(phase), np.sin(phase), np.ones_like(phase)))


def _rss(values):
    return float(values @ values)


class Periodic(Shape):
    """A sinusoid of free wavelength along the travel (cos, sin and the wavelength)."""

    kind = "periodic"
    extra = 3

    def trials(self, measurement):
        """Independent frequencies in the resolvable band (Rayleigh spacing 1/span)."""
        centres, _ = target_clusters(measurement.position_mm)
        if centres.size < 8:
            return 0
        low, high = resolvable_band_per_mm(centres)
        return max(int((high - low) * np.ptp(centres)), 1)

    def trial(self, measurement, current):
        residual_um, position_mm = current.residual_um, measurement.position_mm
        spectrum = amplitude_spectrum(position_mm, residual_um)
        if spectrum is None or spectrum.amplitude_um.size == 0:
            return None
        peak = 1.0 / spectrum.wavelength_mm[int(np.argmax(spectrum.amplitude_um))]
        centres, _ = target_clusters(position_mm)
        step = 1.0 / (5 * np.ptp(centres))
        best = minimize_scalar(
            lambda f: _rss(residual_um - least_squares_fit(residual_um, sinusoid(position_mm, f))),
            bounds=(max(peak - step, step / 2), peak + step), method="bounded",
            options={"xatol": step * 1e-4})
        return Trial(sinusoid(position_mm, best.x), float(1.0 / best.x))

    def describe(self, measurement, trial, fitted_um):
        amplitude = np.ptp(fitted_um) / 2
        return (f"peak at {trial.location:.4g} mm, amplitude {amplitude:.3g} µm; "
                f"{_compare_to_marks(trial.location, measurement.marks)}")


class Direction(Shape):
    """A reversal that changes along the travel (friction or stiffness, not a constant B)."""

    kind = "direction"
    extra = 2

    def trials(self, measurement):
        return 1 if measurement.bidirectional else 0

    def trial(self, measurement, current):
        scaled = _normalised(measurement.position_mm)
        return Trial(np.column_stack((measurement.direction, measurement.direction * scaled)))

    def describe(self, measurement, trial, fitted_um):
        position_mm, direction = measurement.position_mm, measurement.direction
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


class Drift(Shape):
    """A drift along the test's clock (time, else run order): linear and quadratic."""

    kind = "drift"
    extra = 2

    def trials(self, measurement):
        return 1 if measurement.layout.clock_varies_within_groups else 0

    def trial(self, measurement, current):
        return Trial(drift_basis(measurement.layout.clock))

    def describe(self, measurement, trial, fitted_um):
        clock, unit = measurement.layout.clock, measurement.layout.clock_unit
        first, last = np.argmin(clock), np.argmax(clock)
        change = float(fitted_um[last] - fitted_um[first])
        span = float(np.ptp(clock))
        per = "per hour" if unit == "h" else "per run"
        over = f"{span:.2g} h" if unit == "h" else f"{span:.2g} runs"
        return (f"the error drifts {change:+.3g} µm over the test ({over}), {change / span:+.3g} "
                f"µm {per} on average, the same at every target; a drift, not an effect")


class Trend(Shape):
    """A straight line, bow or S-shape along the travel."""

    kind = "trend"
    extra = MAX_TREND_DEGREE

    def trials(self, measurement):
        return MAX_TREND_DEGREE if target_clusters(measurement.position_mm)[0].size >= 4 else 0

    def trial(self, measurement, current):
        return Trial(np.vander(_normalised(measurement.position_mm), MAX_TREND_DEGREE + 1))

    def describe(self, measurement, trial, fitted_um):
        return (f"the residual follows a polynomial of degree up to {MAX_TREND_DEGREE} along "
                f"the travel, {np.ptp(fitted_um):.3g} µm peak to valley")


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
