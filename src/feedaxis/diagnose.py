"""Where the model fails and what is missing: residual analysis and ranking of effects.

The model is refitted to the case; then

- each available effect not yet in the model is fitted on top (all parameters together).
  It is significant when BIC falls by at least ``SIGNIFICANT_DELTA_BIC`` *and* it removes
  at least ``MIN_EXPLAINED_SHARE`` of the residual's sum of squares, so no effect is named
  for a sliver of structure that belongs to something else. The significant ones are
  added and the rest tried again on top of them, so a small effect under a large one is
  still named;
- what is left after all candidates is searched for structure no effect explains:
  a sinusoid of free wavelength, a direction-dependent offset, a drift in time, a trend or
  irregular shape along the travel; each must pass the same BIC test;
- the verdict is ``missing_effect`` when a candidate exists, ``unexplained`` when only
  structure is left, ``adequate`` when the residual is consistent with noise.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar

from .effects import CATALOG, Effect, Model, Parameter
from .fit import FitResult, fit, too_few_samples
from .iso230 import target_groups

SIGNIFICANT_DELTA_BIC = -10.0
MIN_EXPLAINED_SHARE = 0.10
MAX_STRUCTURES = 5
NOISE_RATIO_LIMIT = 1.5
MIN_POINTS_FOR_RATIO = 30
SPECTRUM_OVERSAMPLING = 5
MAX_UNEVEN_FREQUENCIES = 4000
MAX_GRID_FREQUENCIES = 1_000_000  # memory bound of the grid before thinning (8 MB)


@dataclass
class Candidate:
    """A catalog (or user) effect that, fitted on top, explains part of the residual."""

    effect: str
    rms_after_um: float
    delta_bic: float
    evidence: str
    meaning: str
    result: FitResult = field(repr=False)

    def to_json(self):
        return {"effect": self.effect, "rms_after_um": self.rms_after_um,
                "delta_bic": self.delta_bic, "evidence": self.evidence}


@dataclass
class Structure:
    """Residual structure that no effect explains."""

    kind: str
    wavelength_mm: float | None
    amplitude_um: float
    delta_bic: float
    evidence: str
    fitted_um: np.ndarray = field(repr=False)
    basis: np.ndarray | None = field(default=None, repr=False)

    def to_json(self):
        return {"kind": self.kind, "wavelength_mm": self.wavelength_mm,
                "amplitude_um": self.amplitude_um, "evidence": self.evidence}


@dataclass
class Spectrum:
    """Amplitude spectrum of the residual along the travel, with marked wavelengths."""

    wavelength_mm: np.ndarray
    amplitude_um: np.ndarray
    marks: dict


@dataclass
class Diagnosis:
    """Everything :func:`diagnose` found, ready for the CLI, the report and the demo."""

    base: FitResult
    noise_um: float
    noise_source: str
    verdict: str
    candidates: list
    unexplained: list
    skipped: dict
    spectrum: Spectrum

    @property
    def rms_um(self):
        return self.base.rms_um

    def to_json(self):
        return {"rms_um": self.rms_um, "noise_um": self.noise_um, "verdict": self.verdict,
                "candidates": [c.to_json() for c in self.candidates],
                "unexplained": [s.to_json() for s in self.unexplained],
                "noise_source": self.noise_source, "skipped": self.skipped}


def diagnose(case, model, effects=None, progress=None):
    """Diagnose ``model`` on ``case``: refit, rank missing effects, describe the rest.

    Parameters
    ----------
    case : Case
    model : Model
    effects : dict, optional
        Effects to try by name (default: the catalog; add user effects to it).
    progress : callable, optional
        Called with a label before each fit.
    """
    effects = CATALOG if effects is None else effects
    notify = progress or (lambda label: None)
    notify("model")
    base = fit(model, case)
    pending, skipped = {}, {}
    for name, effect in effects.items():
        if name in model:
            continue
        reason = effect.unavailable(case)
        if reason:
            skipped[name] = reason
        else:
            pending[name] = effect
    candidates, left = [], base
    while pending:
        found = []
        for effect in list(pending.values()):
            shortfall = too_few_samples(left.model + effect, case)
            if shortfall:
                skipped[effect.name] = shortfall
                del pending[effect.name]
                continue
            notify(effect.name)
            candidate = _try_effect(case, left, effect)
            if candidate:
                found.append(candidate)
        if not found:
            break
        found.sort(key=lambda c: c.delta_bic)
        while len(found) > 1 and too_few_samples(
                left.model + Model([c.result.model.effects[-1] for c in found]), case):
            found.pop()  # the samples cannot carry them all at once: the weakest waits
        candidates += found
        for candidate in found:
            del pending[candidate.effect]
        left = _with_all(case, left, found)
    noise_um, noise_source = estimate_noise_um(case, left.residual_um)
    unexplained = find_structures(case, left, noise_um, effects)
    verdict = "missing_effect" if candidates else "unexplained" if unexplained else "adequate"
    return Diagnosis(base, noise_um, noise_source, verdict, candidates, unexplained, skipped,
                     residual_spectrum(case, base.residual_um, effects))


def _try_effect(case, base, effect):
    """Fit ``effect`` on top of the base model; a Candidate when it is significant."""
    result = fit(base.model + effect, case)
    delta_bic = result.statistics.bic - base.statistics.bic
    rss_before, rss_after = _rss(base.residual_um), _rss(result.residual_um)
    if delta_bic > SIGNIFICANT_DELTA_BIC or rss_after > (1 - MIN_EXPLAINED_SHARE) * rss_before:
        return None
    contribution = result.model.components(case)[effect.name]
    evidence = effect.evidence(case, result.model.values[effect.name], contribution)
    return Candidate(effect.name, result.rms_um, float(delta_bic), evidence, effect.meaning,
                     result)


def _with_all(case, left, found):
    """``left``'s model with every found effect added (from its fitted values), refitted."""
    if len(found) == 1:
        return found[0].result
    model = left.model
    for candidate in found:
        fitted = candidate.result.model
        model = model + Model((fitted.effects[-1],), fitted.values)
    return fit(model, case)


def _rss(values):
    return float(values @ values)


def _delta_bic(residual_um, fitted_um, n_parameters):
    n = residual_um.size
    return n * np.log(max(_rss(residual_um - fitted_um), 1e-300) / max(_rss(residual_um), 1e-300)) \
        + n_parameters * np.log(n)


def estimate_noise_um(case, residual_um):
    """Measurement noise (µm): the scatter of repeated samples, else point-to-point scatter.

    With repeats (several samples at one target and direction, no time drift left in the
    model's residual) the pooled standard deviation within those groups is the noise. Without
    repeats, the median absolute successive difference along the travel (robust, scaled to a
    standard deviation); short-wave structure left in the residual makes it an upper bound.
    """
    positioning = case.positioning
    groups = target_groups(positioning)
    sizes = np.bincount(groups)
    if np.sum(sizes[sizes > 1] - 1) >= 5:
        means = np.bincount(groups, residual_um) / sizes
        deviations = residual_um - means[groups]
        dof = np.sum(sizes - 1)
        return float(np.sqrt(_rss(deviations) / dof)), "scatter of repeated samples"
    order = np.lexsort((positioning.target_mm, _run_or_time(positioning)))
    steps = np.diff(residual_um[order])
    return (float(1.4826 * np.median(np.abs(steps - np.median(steps))) / np.sqrt(2)),
            "point-to-point scatter along the travel")


def _run_or_time(positioning):
    if positioning.time_s is not None:
        return positioning.time_s
    return positioning.run if positioning.run is not None else np.zeros(positioning.size)


def find_structures(case, left, noise_um, effects):
    """Structure in the residual of the fit ``left`` that no effect explains, strongest first.

    Repeatedly takes the strongest significant structure (periodic, direction, time, trend),
    refits the model together with it (so the model's own parameters are not biased by it)
    and looks again; if nothing is found but the residual is well above the noise, reports
    an irregular shape along the travel.
    """
    structures, current = [], left
    marks = _marked_wavelengths(case.axis, effects)
    for _ in range(MAX_STRUCTURES):
        remaining = current.residual_um
        found = [s for s in (_periodic(case, remaining, marks), _direction(case, remaining),
                             _drift(case, remaining), _trend(case, remaining),
                             _irregular(case, remaining)) if s is not None]
        if not found:
            break
        best = min(found, key=lambda s: s.delta_bic)
        if best.delta_bic > SIGNIFICANT_DELTA_BIC:
            break
        structures.append(best)
        model = current.model + _StructureEffect(len(structures), best.basis)
        if too_few_samples(model, case):
            break
        current = fit(model, case)
    remaining = current.residual_um
    rms_um = float(np.sqrt(np.mean(np.square(remaining))))
    if (not structures and remaining.size >= MIN_POINTS_FOR_RATIO
            and rms_um > NOISE_RATIO_LIMIT * noise_um):
        structures.append(Structure(
            "trend", None, rms_um, 0.0,
            f"residual RMS {rms_um:.3g} µm is {rms_um / noise_um:.1f}x the noise "
            f"({noise_um:.3g} µm) but neither periodic nor smooth: an irregular error "
            "along the travel (a lead-error table would capture it)", remaining))
    return structures


class _StructureEffect(Effect):
    """A found structure as a temporary linear effect, refitted with the model."""

    def __init__(self, number, basis):
        self.name, self.basis = f"structure_{number}", basis
        self.parameters = tuple(Parameter(f"c{i}_um", "um", -1e6, 1e6)
                                for i in range(basis.shape[1]))

    def prepare(self, case):
        return lambda v: self.basis @ np.array([v[p.name] for p in self.parameters])

    def guess(self, case, residual_um):
        coefficients = np.linalg.lstsq(self.basis, residual_um, rcond=None)[0]
        return {p.name: float(c) for p, c in zip(self.parameters, coefficients)}


def _least_squares_structure(residual_um, basis):
    coefficients = np.linalg.lstsq(basis, residual_um, rcond=None)[0]
    return basis @ coefficients


def _structure(kind, wavelength_mm, residual_um, basis, describe):
    """Fit ``basis`` to the residual; ``describe(fitted)`` gives the evidence line."""
    fitted = _least_squares_structure(residual_um, basis)
    return Structure(kind, wavelength_mm, float(np.ptp(fitted) / 2),
                     float(_delta_bic(residual_um, fitted, basis.shape[1] + (kind == "periodic"))),
                     describe(fitted), fitted, basis)


def _normalised(values):
    span = np.ptp(values)
    return (values - values.mean()) / (span if span > 0 else 1.0)


def _periodic(case, residual_um, marks):
    spectrum = _spectrum(case.positioning.target_mm, residual_um)
    if spectrum is None:
        return None
    position_mm = case.positioning.target_mm
    peak = int(np.argmax(spectrum.amplitude_um))
    frequency = 1.0 / spectrum.wavelength_mm[peak]
    step = _frequency_step(position_mm)
    best = minimize_scalar(
        lambda f: _rss(residual_um - _least_squares_structure(residual_um, _sinusoid(position_mm, f))),
        bounds=(max(frequency - step, step / 2), frequency + step), method="bounded",
        options={"xatol": step * 1e-4})
    wavelength_mm = float(1.0 / best.x)
    return _structure("periodic", wavelength_mm, residual_um, _sinusoid(position_mm, best.x),
                      lambda fitted: f"peak at {wavelength_mm:.4g} mm, amplitude "
                                     f"{np.ptp(fitted) / 2:.3g} µm; "
                                     f"{_compare_to_marks(wavelength_mm, marks)}")


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


def _sinusoid(position_mm, frequency_per_mm):
    """Basis cos, sin, 1 at one spatial frequency (1/mm)."""
    phase = 2 * np.pi * frequency_per_mm * position_mm
    return np.column_stack((np.cos(phase), np.sin(phase), np.ones_like(phase)))


def _direction(case, residual_um):
    positioning = case.positioning
    if not positioning.bidirectional:
        return None
    direction = positioning.direction
    basis = np.column_stack((direction, direction * _normalised(positioning.target_mm)))
    return _structure("direction", None, residual_um, basis, lambda fitted: (
        f"approach + and - differ by {np.mean(fitted[direction > 0]) - np.mean(fitted[direction < 0]):+.3g}"
        " µm on average, changing along the travel (friction or stiffness, not a constant "
        "backlash)"))


def _drift(case, residual_um):
    positioning = case.positioning
    if positioning.time_s is None or np.ptp(positioning.time_s) == 0:
        return None
    time_s, position_mm = positioning.time_s, positioning.target_mm
    if np.ptp(position_mm) > 0 and abs(np.corrcoef(time_s, position_mm)[0, 1]) > 0.9:
        return None
    scaled = _normalised(time_s)
    basis = np.column_stack((np.ones_like(scaled), scaled, scaled**2))
    return _structure("time", None, residual_um, basis, lambda fitted: (
        f"the residual drifts by {np.ptp(fitted):.3g} µm over {np.ptp(time_s) / 60:.1f} min "
        "of the test"))


def _trend(case, residual_um):
    position_mm = case.positioning.target_mm
    if np.unique(position_mm).size < 4:
        return None
    scaled = _normalised(position_mm)
    shapes = {1: "a straight line", 2: "a bow", 3: "an S-shape"}
    options = [_structure("trend", None, residual_um, np.vander(scaled, degree + 1),
                          lambda fitted, degree=degree: (
                              f"the residual follows {shapes[degree]} along the travel, "
                              f"{np.ptp(fitted):.3g} µm peak to valley"))
               for degree in shapes]
    return min(options, key=lambda structure: structure.delta_bic)


def _irregular(case, residual_um):
    """Per-target means beyond repeatability: an irregular error along the travel."""
    groups = target_groups(case.positioning)
    sizes = np.bincount(groups)
    if sizes.size < 3 or np.sum(sizes - 1) < sizes.size:
        return None
    basis = (groups[:, None] == np.arange(sizes.size)[None, :]).astype(float)
    return _structure("trend", None, residual_um, basis, lambda fitted: (
        f"the mean error at each target scatters {np.std(fitted):.3g} µm beyond the "
        "repeatability, irregularly along the travel (a lead-error table would capture it)"))


def _marked_wavelengths(axis, effects):
    """{effect name: wavelength (mm)} of the periodic effects this axis defines."""
    marks = {}
    for name, effect in effects.items():
        try:
            wavelength = effect.wavelength_mm(axis)
        except KeyError:
            continue
        if wavelength:
            marks[name] = float(wavelength)
    return marks


def residual_spectrum(case, residual_um, effects=None):
    """Amplitude spectrum of the residual along the travel with the catalog's wavelengths."""
    marks = _marked_wavelengths(case.axis, CATALOG if effects is None else effects)
    spectrum = _spectrum(case.positioning.target_mm, residual_um)
    if spectrum is None:
        return Spectrum(np.array([]), np.array([]), marks)
    return Spectrum(spectrum.wavelength_mm, spectrum.amplitude_um, marks)


def _frequency_step(position_mm):
    return 1.0 / (SPECTRUM_OVERSAMPLING * np.ptp(position_mm))


def _spectrum(position_mm, residual_um):
    """Least-squares amplitude spectrum; FFT on an even grid, Lomb-Scargle otherwise.

    Repeated samples at one position are averaged first. Wavelengths run from the
    travel down to twice the median sample spacing.
    """
    unique_mm, index = np.unique(np.round(position_mm, 9), return_inverse=True)
    if unique_mm.size < 8:
        return None
    means_um = np.bincount(index.ravel(), residual_um) / np.bincount(index.ravel())
    spacing = np.diff(unique_mm)
    step_mm = float(np.median(spacing))
    span_mm = float(np.ptp(unique_mm))
    if np.allclose(spacing, step_mm, rtol=1e-3):
        centred = means_um - means_um.mean()
        n_fft = 1 << int(np.ceil(np.log2(SPECTRUM_OVERSAMPLING * unique_mm.size)))
        frequency = np.fft.rfftfreq(n_fft, d=step_mm)
        amplitude = 2.0 * np.abs(np.fft.rfft(centred, n_fft)) / unique_mm.size
    else:
        from scipy.signal import lombscargle  # 0.5 s import, only for uneven sampling

        frequency_step = _frequency_step(unique_mm)
        band = 0.5 / step_mm - 1.0 / span_mm
        if band > MAX_GRID_FREQUENCIES * frequency_step:  # nearly coincident targets would
            frequency_step = band / MAX_UNEVEN_FREQUENCIES  # ask for billions of points
        frequency = np.arange(1.0 / span_mm, 0.5 / step_mm, frequency_step)
        frequency = frequency[:: max(1, frequency.size // MAX_UNEVEN_FREQUENCIES)]
        amplitude = np.abs(lombscargle(unique_mm, means_um, 2 * np.pi * frequency,
                                       floating_mean=True, normalize="amplitude"))
    keep = (frequency >= 1.0 / span_mm) & (frequency <= 0.5 / step_mm)
    return Spectrum(1.0 / frequency[keep], amplitude[keep], {})
