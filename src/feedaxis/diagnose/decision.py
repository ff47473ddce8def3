"""Where the model fails and what is missing: the decision.

1. The model is fitted; isolated outliers are found (:func:`~.judge.outlier_rows`),
   reported by row and kept out of everything that follows.
2. Where repeats can tell a drift along the test's clock from the targets, the drift is
   added as a nuisance (so it never aliases into backlash or another effect) and reported
   when its F test passes.
3. Stepwise selection: every available effect not yet in the model is fitted on top; each
   is judged by the extra-sum-of-squares F test against the pure error (or, without
   repeats, the residual mean square). The best is accepted at a family-wise error rate
   ``FAMILY_ALPHA`` (Bonferroni over the effects tried), added, and the others re-tested on
   top of it; repeated until none passes.
   Periodic catalog effects whose wavelength the targets cannot resolve are passed over.
4. What is left is searched for structure no effect explains (:mod:`.structures`), with the
   same test; then a lack-of-fit test (repeats) or a serial-correlation test (no repeats).
5. Verdict: ``missing_effect`` when a candidate is named, ``unexplained`` when structure
   (or a drift) is left, ``adequate`` when the lack of fit is consistent with the noise.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..effects import CATALOG
from ..fit import FitResult, fit, too_few_samples
from ..iso230 import target_clusters
from . import judge
from .judge import FAMILY_ALPHA, Layout, Test
from .spectrum import Spectrum, marked_wavelengths, residual_spectrum
from .structures import SHAPES, Context, Drift, Structure, StructureEffect, least_squares_fit

MAX_STRUCTURES = 5
MAX_PHASE_CONCENTRATION = 0.9
FIRST_DATA_ROW = 2


@dataclass
class Candidate:
    """A catalog (or user) effect that, fitted on top, explains part of the residual."""

    effect: str
    rms_after_um: float
    delta_bic: float
    test: Test
    evidence: str
    meaning: str
    result: FitResult = field(repr=False)
    error_scale: float = 1.0

    def sizes(self):
        """{parameter: (value, standard error, unit)} of the named effect; the standard
        errors rest on the pure error where there are repeats (``error_scale``)."""
        effect = self.result.model.effects[-1]
        values = self.result.model.values[self.effect]
        sigma = self.result.uncertainties.get(self.effect, {})
        return {p.name: (values[p.name], self.error_scale * sigma.get(p.name, float("nan")),
                         p.unit) for p in effect.parameters}

    def to_json(self):
        sizes = {name: {"value": value, "standard_error": None if np.isnan(error) else error,
                        "unit": unit} for name, (value, error, unit) in self.sizes().items()}
        return {"effect": self.effect, "rms_after_um": self.rms_after_um,
                "delta_bic": self.delta_bic, "evidence": self.evidence, "parameters": sizes,
                **self.test.to_json()}


@dataclass
class Findings:
    """What a diagnosis of positioning or tracking data found: the refit of the model, the
    noise, the verdict, the missing effects, the unexplained structure, what was skipped."""

    base: FitResult
    noise_um: float
    noise_source: str
    verdict: str
    candidates: list
    unexplained: list
    skipped: dict

    @property
    def rms_um(self):
        return self.base.rms_um

    def to_json(self):
        return {"rms_um": self.rms_um, "noise_um": self.noise_um, "verdict": self.verdict,
                "candidates": [c.to_json() for c in self.candidates],
                "unexplained": [s.to_json() for s in self.unexplained],
                "noise_source": self.noise_source, "skipped": self.skipped}


@dataclass
class Diagnosis(Findings):
    """Everything :func:`diagnose` found, ready for the CLI, the report and the demo."""

    spectrum: Spectrum
    outlier_rows: list = field(default_factory=list)
    test_used: str = ""

    def to_json(self):
        return {**super().to_json(), "outlier_rows": self.outlier_rows,
                "test": self.test_used, "family_alpha": FAMILY_ALPHA}


def diagnose(case, model, effects=None, progress=None):
    """Diagnose ``model`` on ``case``: refit, name missing effects, describe the rest.

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
    first = fit(model, case)
    layout = Layout.of(case.positioning)
    outliers = judge.outlier_rows(layout, case.positioning.target_mm, first.residual_um)
    if outliers.size:
        keep = np.ones(case.positioning.size, dtype=bool)
        keep[outliers] = False
        case, layout = without_samples(case, keep), layout.subset(keep)
        first = fit(model, case)
    pending, skipped = _available(case, model, effects)
    context = Context(case.positioning.target_mm, case.positioning.direction,
                      case.positioning.bidirectional, layout,
                      marked_wavelengths(case.axis, effects))
    candidates, nuisances, left = _select(case, layout, context, first, pending, skipped,
                                          notify)
    noise_um, noise_source = estimate_noise_um(case, left.residual_um, layout)
    unexplained = nuisances + find_structures(case, layout, context, left)
    verdict = "missing_effect" if candidates else "unexplained" if unexplained else "adequate"
    test_used = (f"{judge.PURE_ERROR if layout.has_repeats else judge.RESIDUAL_MEAN_SQUARE}, "
                 f"family-wise error rate {FAMILY_ALPHA:g} over the diagnosis (Bonferroni)")
    return Diagnosis(first, noise_um, noise_source, verdict, candidates, unexplained, skipped,
                     residual_spectrum(case, first.residual_um, effects),
                     [int(i) + FIRST_DATA_ROW for i in outliers], test_used)


def without_samples(case, keep):
    """``case`` with only the positioning samples ``keep`` (boolean mask)."""
    positioning = case.positioning
    kept = {name: None if getattr(positioning, name) is None else getattr(positioning, name)[keep]
            for name in ("target_mm", "error_um", "direction", "run", "time_s", "ambient_C")}
    return replace(case, positioning=replace(positioning, **kept))


def _available(case, model, effects):
    """({name: effect} to try, {name: reason} passed over)."""
    pending, skipped = {}, {}
    for name, effect in effects.items():
        if name in model:
            continue
        reason = effect.unavailable(case) or unresolvable(case, effect)
        if reason:
            skipped[name] = reason
        else:
            pending[name] = effect
    return pending, skipped


def unresolvable(case, effect):
    """Why the targets cannot resolve a periodic effect's wavelength (None when they can)."""
    try:
        wavelength_mm = effect.wavelength_mm(case.axis)
    except KeyError:
        return None
    if not wavelength_mm:
        return None
    centres_mm, _ = target_clusters(case.positioning.target_mm)
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


def _select(case, layout, context, first, pending, skipped, notify):
    """Stepwise: (candidates, nuisance structures, final fit) at ``FAMILY_ALPHA``.

    An effect the samples cannot carry on top of the model so far goes to ``skipped``.
    """
    left = _with_drift(case, context, first, notify)
    candidates = []
    while pending:
        tested = []
        for effect in list(pending.values()):
            shortfall = too_few_samples(left.model + effect, case)
            if shortfall:
                skipped[effect.name] = shortfall
                del pending[effect.name]
                continue
            notify(effect.name)
            result = fit(left.model + effect, case)
            tested.append((judge.extra_ss_test(layout, left.residual_um, result.residual_um,
                                               len(effect.parameters), result.statistics.n_free),
                           effect, result))
        if not tested:
            break
        test, effect, result = min(tested, key=lambda item: item[0].p_value)
        if not judge.accepts(test.p_value, len(tested)):
            break
        candidates.append(_candidate(case, layout, left, effect, result, test))
        del pending[effect.name]
        left = result
    return candidates, _drift_finding(case, layout, context, left, notify), left


def _with_drift(case, context, first, notify):
    """The model with a drift along the clock as a nuisance, whenever repeats show one can
    be told from the targets: in a bidirectional test + and - runs alternate, so an
    unmodelled drift would alias into the reversal."""
    if not Drift().trials(context):
        return first
    model = first.model + StructureEffect("drift", Drift().basis(context)[0])
    if too_few_samples(model, case):
        return first
    notify("drift")
    return fit(model, case)


def _drift_finding(case, layout, context, left, notify):
    """The drift in the final model (effects named), reported when its F test passes."""
    if "drift" not in left.model:
        return []
    notify("drift")
    drift = left.model.effects[left.model.names.index("drift")]
    others = [e for e in left.model.effects if e is not drift]
    without = fit(type(left.model)(others, left.model.values), case)
    test = judge.extra_ss_test(layout, without.residual_um, left.residual_um, Drift.extra,
                               left.statistics.n_free)
    if not judge.accepts(test.p_value, 1):
        return []
    fitted = drift.prepare(case)(left.model.values["drift"])
    return [Structure("drift", None, float(np.ptp(fitted) / 2), test,
                      f"{Drift().describe(context, fitted)} ({test.describe()})", fitted,
                      drift.basis)]


def _candidate(case, layout, left, effect, result, test):
    """The named effect, its result's model without nuisances (so it can be used as is)."""
    scale = _pure_error_scale(layout, result)
    if any(isinstance(e, StructureEffect) for e in result.model.effects):
        clean = [e for e in result.model.effects if not isinstance(e, StructureEffect)]
        values = {e.name: result.model.values[e.name] for e in clean}
        result = replace(result, model=type(result.model)(clean, values))
    contribution = result.model.components(case)[effect.name]
    evidence = effect.evidence(case, result.model.values[effect.name], contribution)
    return Candidate(effect.name, result.rms_um,
                     float(result.statistics.bic - left.statistics.bic), test,
                     f"{evidence} ({test.describe()})", effect.meaning, result, scale)


def _pure_error_scale(layout, result):
    """√(pure-error variance / residual variance): turns the fit's standard errors (from
    its residual, unmodelled shape included) into ones resting on the repeatability."""
    if not layout.has_repeats:
        return 1.0
    statistics = result.statistics
    residual_variance = (statistics.rms_um**2 * statistics.n_points
                         / max(statistics.n_points - statistics.n_free, 1))
    pure_variance = (layout.pure_error_ss(result.residual_um)
                     / max(layout.pure_dof - statistics.n_free, 1))
    return float(np.sqrt(pure_variance / residual_variance)) if residual_variance > 0 else 1.0


def estimate_noise_um(case, residual_um, layout=None):
    """Measurement noise (µm): the scatter of repeated samples, else point-to-point scatter.

    With repeats the pooled standard deviation within the groups is the noise. Without,
    the median absolute successive difference along the travel (robust, scaled to a standard
    deviation); short-wave structure left in the residual makes it an upper bound.
    """
    layout = layout or Layout.of(case.positioning)
    if layout.pure_dof >= 5:
        return (float(np.sqrt(layout.pure_error_ss(residual_um) / layout.pure_dof)),
                "scatter of repeated samples")
    positioning = case.positioning
    order = np.lexsort((positioning.target_mm, _run_or_time(positioning)))
    steps = np.diff(residual_um[order])
    return (float(judge.MAD_TO_SIGMA * np.median(np.abs(steps - np.median(steps))) / np.sqrt(2)),
            "point-to-point scatter along the travel")


def _run_or_time(positioning):
    if positioning.time_s is not None:
        return positioning.time_s
    return positioning.run if positioning.run is not None else np.zeros(positioning.size)


def find_structures(case, layout, context, left):
    """Structure in the residual of ``left`` that no effect explains, strongest first.

    At each step every shape is fitted to the residual and F-tested; the best is accepted at
    ``FAMILY_ALPHA`` with Bonferroni over all shapes tried (a free-wavelength search counts
    every resolvable frequency), refitted with the model and the search repeated. Then the
    rest is tested for lack of fit (repeats) or serial correlation (no repeats): an
    irregular error along the travel.
    """
    structures, current = [], left
    shapes = [shape() for shape in SHAPES]
    for _ in range(MAX_STRUCTURES):
        residual = current.residual_um
        options, tried = [], 0
        for shape in shapes:
            trials = shape.trials(context)
            basis, wavelength_mm = shape.basis(context, residual) if trials else (None, None)
            if basis is None:
                continue
            tried += trials
            fitted = least_squares_fit(residual, basis)
            options.append((judge.extra_ss_test(layout, residual, residual - fitted, shape.extra,
                                                current.statistics.n_free + shape.extra),
                            shape, basis, wavelength_mm, fitted))
        if not options:
            break
        test, shape, basis, wavelength_mm, fitted = min(options, key=lambda o: o[0].p_value)
        if not judge.accepts(test.p_value, tried):
            break
        evidence = shape.describe(context, fitted, wavelength_mm)
        structures.append(Structure(shape.kind, wavelength_mm, float(np.ptp(fitted) / 2), test,
                                    f"{evidence} ({test.describe()})", fitted, basis))
        shapes.remove(shape)
        model = current.model + StructureEffect(f"structure_{len(structures)}", basis)
        if too_few_samples(model, case):
            break
        current = fit(model, case)
    irregular = _irregular(case, layout, current)
    return structures + ([irregular] if irregular else [])


def _irregular(case, layout, current):
    """An irregular error along the travel: lack of fit beyond the noise, no shape found."""
    residual = current.residual_um
    n_within = sum(len(e.parameters) for e in current.model.effects if e.name == "drift")
    n_between = current.statistics.n_free - n_within
    if layout.has_repeats and layout.n_groups > n_between + 1:
        test = judge.lack_of_fit_test(layout, residual, n_between, n_within)
        means = layout.group_means(residual)
        what = (f"the mean error at each target scatters {np.std(means):.3g} µm beyond the "
                f"repeatability")
    elif not layout.has_repeats and residual.size >= 30:
        test = judge.serial_correlation_test(case.positioning.target_mm, residual)
        means = residual
        what = (f"residual RMS {np.sqrt(np.mean(residual**2)):.3g} µm, neighbouring samples "
                "alike")
    else:
        return None
    if not judge.accepts(test.p_value, 1):
        return None
    return Structure("irregular", None, float(np.ptp(means) / 2), test,
                     f"{what}, irregularly along the travel: a lead-error table would capture "
                     f"it ({test.describe()})", means)
