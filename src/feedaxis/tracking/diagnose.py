"""Where a tracking model fails and what is missing (the positioning loop's shape, in time).

The model is refitted to the case; then

- each tracking effect not yet in the model is fitted on top; it is significant when the
  F test with the residual's autocorrelation accounted for (:mod:`.tests`) rejects "no
  effect" at ``FAMILY_ALPHA`` shared (Bonferroni) among the effects tried in that round.
  The significant one leaving the smallest residual is named and added, and the rest tried
  again on top of it (forward selection: the tracking effects overlap, viscous friction
  acting exactly as plant damping, so adding all significant ones at once would name
  effects that only stand in for the first);
- the residual left is searched for structure no effect explains, each kind tested at
  ``FAMILY_ALPHA`` shared among the kinds: a sinusoid of free frequency (an unknown
  periodic force, e.g. a cutting force at the tooth-passing frequency, seed 002 Table 2),
  a constant force (the loop's response to a steady force), error locked to the velocity
  reversals of another shape than the friction effects give, a trend in time;
- the verdict is ``missing_effect`` when a candidate exists, ``unexplained`` when only
  structure is left, ``adequate`` when the residual is consistent with coloured noise.

Measured on seeded cases (tests/test_tracking_loop.py, benchmarks/bench_tracking_fit.py):
the false-alarm rate under the null and the power for friction and a periodic force.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar
from threadpoolctl import threadpool_limits

from ..diagnose.decision import Findings
from ..effects import CATALOG
from ..fit import FitResult
from ..physics.servo import simulate
from ..effects.tracking import is_tracking_effect
from .fit import fit
from .model import Record, servo_params
from .tests import autocorrelation_time, nested_p_value, peak_p_value

FAMILY_ALPHA = 1e-3
MAX_STRUCTURES = 4
RESOLUTION_UM = 1e-3  # 1 nm: structure below it is rounding, not a measurement
REVERSAL_WINDOW_S = 0.2
REVERSAL_BINS = 8
UNIFORM_SAMPLING_TOLERANCE = 0.01


@dataclass
class Candidate:
    """A tracking effect that, fitted on top, explains part of the residual."""

    effect: str
    rms_after_um: float
    delta_bic: float
    p_value: float
    evidence: str
    meaning: str
    result: FitResult = field(repr=False)

    def to_json(self):
        return {"effect": self.effect, "rms_after_um": self.rms_after_um,
                "delta_bic": self.delta_bic, "p_value": self.p_value, "evidence": self.evidence}


@dataclass
class Structure:
    """Residual structure in time that no effect explains."""

    kind: str
    frequency_hz: float | None
    amplitude_um: float
    p_value: float
    evidence: str
    fitted_um: np.ndarray = field(repr=False)
    n_parameters: int = 1

    def to_json(self):
        return {"kind": self.kind, "frequency_hz": self.frequency_hz,
                "amplitude_um": self.amplitude_um, "p_value": self.p_value,
                "evidence": self.evidence}


@dataclass
class TrackingDiagnosis(Findings):
    """Everything :func:`diagnose` found, for the CLI and the report."""

    final: FitResult = field(repr=False)


def diagnose(case, model, effects=None, progress=None):
    """Diagnose the tracking ``model`` on ``case``: refit, name missing effects, describe
    the rest.

    Parameters
    ----------
    case : Case
        With tracking.csv and ``[servo]``.
    model : Model
    effects : dict, optional
        Effects by name (default: the catalog); its tracking effects are tried.
    progress : callable, optional
        Called with a label before each fit.
    """
    with threadpool_limits(limits=1, user_api="blas"):
        return _diagnose(case, model, effects, progress)


def _diagnose(case, model, effects, progress):
    effects = CATALOG if effects is None else effects
    notify = progress or (lambda label: None)
    notify("model")
    base = fit(model, [case])
    pending, skipped = {}, {}
    for name, effect in effects.items():
        if name in model:
            continue
        reason = effect.unavailable(case) if is_tracking_effect(effect) else (
            "a positioning effect; this diagnosis compares tracking.csv")
        if reason:
            skipped[name] = reason
        else:
            pending[name] = effect
    candidates, left = [], base
    while pending:
        found = []
        for effect in pending.values():
            notify(effect.name)
            candidate = _try_effect(case, left, effect, FAMILY_ALPHA / len(pending))
            if candidate:
                found.append(candidate)
        if not found:
            break
        best = min(found, key=lambda c: c.rms_after_um)
        candidates.append(best)
        del pending[best.effect]
        left = best.result
    unexplained, final = find_structures(case, left)
    remaining = final.residual_um
    tau = autocorrelation_time(remaining)
    verdict = "missing_effect" if candidates else "unexplained" if unexplained else "adequate"
    return TrackingDiagnosis(
        base, float(np.sqrt(np.mean(remaining ** 2))),
        f"residual left after the effects and structures found (autocorrelation time "
        f"{tau:.1f} samples)", verdict, candidates, unexplained, skipped, final)


def _try_effect(case, base, effect, alpha):
    """Fit ``effect`` on top of ``base``; a Candidate when the coloured-noise F test rejects."""
    result = fit(base.model + effect, [case])
    p_value = nested_p_value(_rss(base.residual_um), _rss(result.residual_um),
                             result.residual_um.size, base.statistics.n_free,
                             len(effect.parameters), result.residual_um)
    explained_um = np.sqrt(max(base.rms_um ** 2 - result.rms_um ** 2, 0.0))
    if p_value >= alpha or explained_um < RESOLUTION_UM:
        return None
    contribution = base.residual_um - result.residual_um
    evidence = effect.evidence(case, result.model.values[effect.name], contribution)
    return Candidate(effect.name, result.rms_um,
                     float(result.statistics.bic - base.statistics.bic), p_value,
                     f"{evidence} (p = {p_value:.2g}, coloured-noise F test)", effect.meaning,
                     result)


def _rss(values):
    return float(values @ values)


def find_structures(case, left):
    """Structure in time in the residual of ``left``, strongest first; after each, the model
    is refitted with the structures taken off the data (so its parameters are not bent by
    them) and the search repeated."""
    structures, current = [], left
    residual = np.array(left.residual_um)
    n_free = left.statistics.n_free
    for _ in range(MAX_STRUCTURES):
        found = [s for s in (_periodic(case, current, residual),
                             _constant_force(case, current, residual, n_free),
                             _reversals(case, residual, n_free), _trend(case, residual, n_free))
                 if s is not None and s.amplitude_um >= RESOLUTION_UM]
        if not found:
            break
        best = min(found, key=lambda s: s.p_value)
        if best.p_value >= FAMILY_ALPHA / len(found):
            break
        structures.append(best)
        n_free += best.n_parameters
        current = fit(current.model, [case], offset_um=sum(s.fitted_um for s in structures))
        residual = current.residual_um
    return structures, current


def _regress(residual, basis):
    coefficients = np.linalg.lstsq(basis, residual, rcond=None)[0]
    return coefficients, basis @ coefficients


def _nested_structure(residual, basis, n_free):
    """(coefficients, fitted, p-value) of ``basis`` regressed on ``residual``."""
    coefficients, fitted = _regress(residual, basis)
    p_value = nested_p_value(_rss(residual), _rss(residual - fitted), residual.size, n_free,
                             basis.shape[1], residual - fitted)
    return coefficients, fitted, p_value


def _uniform_step_s(time_s):
    steps = np.diff(time_s)
    step = float(np.median(steps))
    return step if np.max(np.abs(steps - step)) <= UNIFORM_SAMPLING_TOLERANCE * step else None


def _sinusoid(time_s, frequency_hz):
    phase = 2.0 * np.pi * frequency_hz * (time_s - time_s[0])
    return np.column_stack((np.cos(phase), np.sin(phase), np.ones_like(phase)))


def _periodic(case, left, residual):
    """The strongest sinusoid, its frequency refined between the neighbouring bins."""
    time_s = case.tracking.time_s
    step_s = _uniform_step_s(time_s)
    if step_s is None or residual.size < 8:
        return None
    peak_hz, p_value, ratio = peak_p_value(residual, step_s)
    bin_hz = 1.0 / (residual.size * step_s)
    refined = minimize_scalar(
        lambda f: _rss(residual - _regress(residual, _sinusoid(time_s, f))[1]),
        bounds=(max(peak_hz - bin_hz, 0.5 * bin_hz), peak_hz + bin_hz),
        method="bounded", options={"xatol": 1e-4 * bin_hz})
    best_hz = float(refined.x)
    phase = 2.0 * np.pi * best_hz * time_s
    basis = np.column_stack([_loop_response_um(case, left.model, np.cos(phase)),
                             _loop_response_um(case, left.model, np.sin(phase))])
    coefficients, fitted = _regress(residual, basis)
    amplitude_um = float(np.hypot(*_regress(residual, _sinusoid(time_s, best_hz))[0][:2]))
    return Structure("periodic", best_hz, amplitude_um, p_value,
                     f"a sinusoid at {best_hz:.4g} Hz, {amplitude_um:.3g} µm in the residual "
                     f"(whitened periodogram {ratio:.0f}x its mean level, family-wise "
                     f"p = {p_value:.2g}): the loop's response to a force of "
                     f"{np.hypot(*coefficients):.3g} N at that frequency (e.g. a cutting force "
                     "at the tooth-passing frequency)", fitted, 3)


def _loop_response_um(case, model, disturbance_N):
    """Change of the predicted deviation (µm) when ``disturbance_N`` is added to the case's."""
    record = Record.of(case)
    tracking = case.tracking
    known = tracking.disturbance_N if tracking.disturbance_N is not None else 0.0
    params = servo_params(case.axis, model)
    moved = simulate(params, tracking.time_s, tracking.reference_mm, known + disturbance_N,
                     record.counts)
    return (moved - tracking.reference_mm) * 1e3 - record.predicted_um(params)


def _constant_force(case, left, residual, n_free):
    """A steady force: the fitted loop's response to 1 N, scaled."""
    response = _loop_response_um(case, left.model, np.ones_like(residual))
    coefficients, fitted, p_value = _nested_structure(residual, response[:, None], n_free)
    return Structure("constant_force", None, float(np.max(np.abs(fitted))), p_value,
                     f"a steady force of {coefficients[0]:+.3g} N acting on the axis "
                     f"(p = {p_value:.2g})", fitted)


def _reversal_basis(time_s, reference_mm):
    """Columns: the new direction's sign in each of REVERSAL_BINS time bins after a reversal."""
    velocity = np.gradient(reference_mm, time_s)
    direction = np.sign(velocity)
    turns = np.flatnonzero(np.diff(direction) != 0) + 1
    basis = np.zeros((time_s.size, REVERSAL_BINS))
    width = REVERSAL_WINDOW_S / REVERSAL_BINS
    for turn in turns:
        since = time_s[turn:] - time_s[turn]
        inside = since < REVERSAL_WINDOW_S
        rows = turn + np.flatnonzero(inside)
        basis[rows, (since[inside] / width).astype(int)] += direction[turn]
    return basis, turns.size


def _reversals(case, residual, n_free):
    """Error locked to the reversals of another shape: a free profile over the window."""
    basis, count = _reversal_basis(case.tracking.time_s, case.tracking.reference_mm)
    if count == 0:
        return None
    _, fitted, p_value = _nested_structure(residual, basis, n_free)
    return Structure("reversal", None, float(np.max(np.abs(fitted))), p_value,
                     f"the residual takes a repeatable shape over {REVERSAL_WINDOW_S:g} s after "
                     f"each of the {count} velocity reversals (p = {p_value:.2g}): a friction "
                     "law other than Coulomb plus viscous (Stribeck, stick-slip), or backlash",
                     fitted, REVERSAL_BINS)


def _trend(case, residual, n_free):
    """A linear drift in time (thermal growth, a drifting encoder)."""
    time_s = case.tracking.time_s
    centred = (time_s - time_s.mean())[:, None]
    coefficients, fitted, p_value = _nested_structure(residual, centred, n_free)
    return Structure("trend", None, float(np.max(np.abs(fitted))), p_value,
                     f"the residual drifts {coefficients[0]:+.3g} µm/s over the record "
                     f"(p = {p_value:.2g})", fitted)
