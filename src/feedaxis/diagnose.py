"""Where the model fails and what is missing: one diagnosis for every kind of measurement.

The measurement (:mod:`feedaxis.measurement`) supplies what differs between kinds: its
noise model, its outliers, its nuisances, its shapes of structure; the decision is this:

1. The model is refitted as ``feedaxis fit`` fits it (:func:`feedaxis.fit.fit_with_artefacts`):
   the outliers the measurement finds are reported by row (those following the motion's
   start or stop as transients) and kept out of everything that follows; the nuisances
   the measurement models with every fit (a drift along a positioning test's clock, so it
   never aliases into backlash) are fitted beside the effects, each reported when its test
   passes. So ``fit`` saves what the diagnosis estimates.
3. Stepwise selection: every available effect acting on the measurement and not yet in the
   model is fitted on top and judged by the extra-sum-of-squares F test of the
   measurement's noise model (:mod:`feedaxis.stats.noise`). The best (smallest p-value) is
   accepted by the one family-wise policy (:func:`feedaxis.stats.judge.accepts`:
   ``FAMILY_ALPHA`` split over the measurement's stages, Bonferroni over the effects
   tried), added, and the others re-tested on top of it, until none passes.
4. What is left is searched for structure no effect explains, with the measurement's
   shapes and the same policy (Bonferroni over every shape tried, a free-frequency search
   counting its resolvable frequencies); each structure found is added as a linear basis
   and the model refitted. Then the measurement's last test for an irregular lack of fit.
   A significant effect the data show to be something else (a catalog wavelength standing
   in for a periodic error at another wavelength) is passed over with the reason.
5. Verdict: ``missing_effect`` when an effect is named, ``unexplained`` when structure (or
   a nuisance) is left, ``undetermined`` when the samples cannot tell noise from structure
   (one pass without replicates: the reason is given), ``adequate`` when the residual is
   consistent with the noise model, which every verdict names.

Structure and effects below ``RESOLUTION_UM`` are rounding, never named.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .effects import CATALOG, BasisEffect, Model
from .fit import (FD_STEP, FitResult, ParameterLayout, Problem, Statistics, fit,
                  fit_with_artefacts, too_few_samples)
from .measurement import kinds_for, measurement_of
from .measurement.base import NoStart
from .memory import give_back_freed_memory
from .physics.threads import one_blas_thread
from .stats.judge import FAMILY_ALPHA, Test, accepts
from .stats.linear import projection

MAX_STRUCTURES = 5
RESOLUTION_UM = 1e-3  # 1 nm: an effect or structure smaller is rounding, not a measurement
# The level of the score screen before a fit (:func:`_tried`): 30 times the most liberal
# level at which the policy names an effect (FAMILY_ALPHA over three stages), so an effect
# the fit would name passes it; its rates are measured by benchmarks/bench_friction_screen.py
SCREEN_ALPHA = 0.01


@dataclass
class Candidate:
    """An effect that, fitted on top, explains part of the residual."""

    effect: str
    rms_after_um: float
    delta_bic: float
    test: Test
    evidence: str
    meaning: str
    result: FitResult = field(repr=False)
    error_scale: float = 1.0
    joint: FitResult | None = field(default=None, repr=False)  # sizes from the last fit

    @property
    def named(self):
        """The named effect (an :class:`~feedaxis.effects.Effect`)."""
        return self.result.model.effects[self.result.model.names.index(self.effect)]

    def sizes(self):
        """{parameter: (value, standard error, unit)} of the named effect; the standard
        errors rest on the noise model's scale (the pure error where there are repeats)."""
        sized = self.joint or self.result
        effect = sized.model.effects[sized.model.names.index(self.effect)]
        values = sized.model.values[self.effect]
        sigma = sized.uncertainties.get(self.effect, {})
        return {p.name: (values[p.name], self.error_scale * sigma.get(p.name, float("nan")),
                         p.unit) for p in effect.parameters}

    def to_json(self):
        sizes = {name: {"value": value, "standard_error": None if np.isnan(error) else error,
                        "unit": unit} for name, (value, error, unit) in self.sizes().items()}
        return {"effect": self.named.effect, "axis": self.named.axis, "add": self.effect,
                "rms_after_um": self.rms_after_um,
                "delta_bic": self.delta_bic, "evidence": self.evidence, "parameters": sizes,
                **self.test.to_json()}


@dataclass
class Structure:
    """A structure found in the residual, with its test; ``location`` (a wavelength in mm
    along the travel, a frequency in Hz in time, or None) under ``location_key``, and
    ``details`` (JSON fields the shape adds: a burst's ``start_s``, ``end_s``)."""

    kind: str
    location_key: str
    location: float | None
    amplitude_um: float
    test: Test
    evidence: str
    fitted_um: np.ndarray = field(repr=False)
    basis: np.ndarray | None = field(default=None, repr=False)
    details: dict = field(default_factory=dict)

    @property
    def wavelength_mm(self):
        return self.location if self.location_key == "wavelength_mm" else None

    @property
    def frequency_hz(self):
        return self.location if self.location_key == "frequency_hz" else None

    def to_json(self):
        return {"kind": self.kind, self.location_key: self.location, **self.details,
                "amplitude_um": self.amplitude_um, "evidence": self.evidence,
                **self.test.to_json()}


@dataclass
class Diagnosis:
    """Everything :func:`diagnose` found on the samples of one kind of measurement (read
    from ``file``): the refit of the model (``base``), the noise and where it comes from,
    the verdict (and, when ``undetermined``, why), the missing effects, the unexplained
    structure, what was passed over, the outliers and transients left out, the axis's
    repeatability against its systematic error, the test that decided, the last fit."""

    measurement: str
    file: str
    base: FitResult
    noise_um: float
    noise_source: str
    verdict: str
    candidates: list
    unexplained: list
    skipped: dict
    outlier_rows: list
    test_used: str
    final: FitResult = field(repr=False)
    transient_rows: list = field(default_factory=list)
    undetermined_reason: str | None = None
    repeatability: dict | None = None

    @property
    def rms_um(self):
        return self.base.rms_um

    def to_json(self):
        return {"measurement": self.measurement, "rms_um": self.rms_um,
                "noise_um": self.noise_um, "verdict": self.verdict,
                "undetermined_reason": self.undetermined_reason,
                "candidates": [c.to_json() for c in self.candidates],
                "unexplained": [s.to_json() for s in self.unexplained],
                "noise_source": self.noise_source, "skipped": self.skipped,
                "outlier_rows": self.outlier_rows, "transient_rows": self.transient_rows,
                "repeatability": self.repeatability, "test": self.test_used,
                "family_alpha": FAMILY_ALPHA}


@one_blas_thread
def diagnose(case, model, effects=None, progress=None, kind=None, measurement=None):
    """Diagnose ``model`` on ``case``: refit, name missing effects, describe the rest.

    Parameters
    ----------
    case : Case
    model : Model
    effects : dict, optional
        Effects to try by name (default: the catalog; add user effects to it).
    progress : callable, optional
        Called with a label before each fit.
    kind : str, optional
        The kind of measurement (default: the model's, else the first the case holds).
    measurement : Measurement, optional
        The samples of ``case`` already chosen (by :func:`feedaxis.analysis.analyse`).
    """
    effects = CATALOG if effects is None else effects
    notify = progress or (lambda label: None)
    notify("model")
    if measurement is None:
        measurement = measurement_of(case, kind or kinds_for([case], model)[0])
    measurement.refitter = Refitter(measurement, effects)
    try:
        base = fit_with_artefacts(model, measurement)
    except NoStart as missing:
        return _unstarted(measurement, model, missing.message)
    measurement = base.measurements[0]
    if measurement.refitter is None:  # the samples without the outliers: refits of their own
        measurement.refitter = Refitter(measurement, effects)
    stages = len(measurement.stages)
    pending, skipped = _available(measurement, model, effects)
    candidates, left = _select(measurement, base, pending, skipped, stages, notify)
    candidates, left = _withdraw(measurement, candidates, left, pending, skipped)
    candidates = [_final_sizes(measurement, c, left) for c in candidates]
    recorded, left = _recorded(measurement, left, pending, stages)
    candidates += recorded
    for candidate in recorded:
        skipped.pop(candidate.effect, None)
    unexplained = _nuisance_findings(measurement, left, stages, notify)
    structures, final = find_structures(measurement, left, measurement.shapes(effects), stages,
                                        notify)
    unexplained += structures
    reason = None if candidates or unexplained else measurement.undetermined(final, stages)
    noise_um, noise_source = measurement.noise.estimate_um(final.residual_um)
    verdict = ("missing_effect" if candidates else "unexplained" if unexplained
               else "undetermined" if reason else "adequate")
    test_used = (f"{measurement.noise.name}, family-wise error rate {FAMILY_ALPHA:g} over the "
                 f"diagnosis (Bonferroni over its {stages} stages and the terms tried)")
    return Diagnosis(measurement.kind, measurement.file, base, noise_um, noise_source, verdict,
                     candidates, unexplained, skipped, base.artefacts["outlier_rows"],
                     test_used, final, base.artefacts["transient_rows"], reason,
                     measurement.repeatability())


class Refitter:
    """Refits of a measurement's samples for its hooks (``Measurement.refitter``):
    ``refitter(model, names)`` fits ``model`` with the catalog effects ``names`` added;
    ``with_basis(model, basis)`` fits it with fixed columns added and returns (the fit, the
    columns' part of its prediction)."""

    def __init__(self, measurement, catalog):
        self.measurement, self.catalog = measurement, catalog
        self._fits = {}

    def __call__(self, model, names=()):
        for name in names:
            model = model + self.catalog[name]
        return self.fit(model)

    def fit(self, model):
        """``fit(model, measurement)``, once per model where the measurement's hooks refit
        what the selection fitted already (the same effects, the same start: the same
        fit; ``Measurement.refits_selection``)."""
        if not self.measurement.refits_selection:
            return fit(model, self.measurement)
        key = (tuple(id(e) for e in model.effects),
               repr([sorted(model.values[name].items()) for name in model.names]))
        if key not in self._fits:
            self._fits[key] = fit(model, self.measurement)
        return self._fits[key]

    def nuisance_test(self, left, name, extra):
        """:func:`nuisance_test` of these samples."""
        return nuisance_test(self.measurement, left, name, extra)

    def with_basis(self, model, basis):
        columns = BasisEffect("columns", basis)
        result = fit(model + columns, self.measurement)
        return result, columns.prepare(self.measurement.case)(result.model.values["columns"])


def _fit(model, measurement):
    """``fit(model, measurement)``, through the measurement's :class:`Refitter` where it
    has its own (its fits are kept for the hooks)."""
    refitter = measurement.refitter
    if refitter is not None and refitter.measurement is measurement:
        return refitter.fit(model)
    return fit(model, measurement)


def _unstarted(measurement, model, reason):
    """The ``undetermined`` diagnosis of samples no model could be started on: ``reason``
    says what is missing; the residual shown is the deviation itself."""
    measured = np.asarray(measurement.measured_um, dtype=float)
    base = FitResult(model, Statistics.of(measured, measured, 0), measured, measured,
                     measurements=[measurement])
    noise_um, noise_source = measurement.noise.estimate_um(measured)
    return Diagnosis(measurement.kind, measurement.file, base, noise_um, noise_source,
                     "undetermined", [], [], {}, [], "none: no model could be started", base,
                     [], f"no model could be started on the samples: {reason}")


def _available(measurement, model, effects):
    """({name: effect} to try, {name: reason} passed over)."""
    pending, skipped = {}, {}
    for name, effect in effects.items():
        if name in model:
            continue
        reason = measurement.unavailable(effect) or measurement.unresolvable(effect)
        if reason:
            skipped[name] = reason
        else:
            pending[name] = effect
    return pending, skipped


def _explained_um(before, after):
    return float(np.sqrt(max(before.rms_um ** 2 - after.rms_um ** 2, 0.0)))


def _select(measurement, left, pending, skipped, stages, notify):
    """Stepwise: (candidates, final fit). An effect the samples cannot carry on top of the
    model so far goes to ``skipped``."""
    candidates = []
    while pending:
        tested = []
        for effect in list(pending.values()):
            shortfall = too_few_samples(left.model + effect, [measurement])
            if shortfall:
                skipped[effect.name] = shortfall
                del pending[effect.name]
        _screen_together(measurement, left, pending)
        for effect in list(pending.values()):
            notify(effect.name)
            give_back_freed_memory(measurement.size)
            tested.append(_tried(measurement, left, effect, pending))
        # p-values alike (each underflows to 0 where effects explain thousands of noise
        # variances) keep the order of what the candidates leave, the least first
        tested = [item for _, item in sorted(tested, key=lambda pair: pair[0])]
        named = _best_candidate(measurement, left, tested, pending, skipped, stages)
        if named is None:
            break
        test, effect, result = named
        result, test = _without_idle_companions(measurement, left, effect, result, test,
                                                stages)
        for joined in [e for e in result.model.effects if e.name in pending]:
            candidates.append(_candidate(measurement, left, joined, result, test))
            del pending[joined.name]
        left.plain = None  # the nuisances' test refits once the model moves on: let it go
        left = result
    return candidates, left


def _tried(measurement, left, effect, pending):
    """(the residual sum of squares ``effect`` leaves on top of ``left``, (its test, it, its
    fit or None)): fitted in full (with the effects it is fitted with, the test counting
    them), or screened by one linearised step (:func:`_screened_residual`). An effect
    always fitted that is ``score_screened`` is first screened by its score test, the step
    from its neutral values with the exact sensitivities (:func:`_score_screens`), and
    fitted only where that test passes at ``SCREEN_ALPHA``."""
    joined = _joined(left.model, effect, pending)
    if effect.additive or not effect.screened:
        if _score_screens(measurement, left, effect, joined):
            after_um = _screened_residual(measurement, left, effect, exact=True)
            test = _extra_test(measurement, left, after_um, len(effect.parameters))
            if test.p_value >= SCREEN_ALPHA:
                return float(after_um @ after_um), (test, effect, None)
        result = _fit(joined, measurement)
        after_um = result.residual_um
        extra = sum(len(e.parameters) for e in joined.effects if e.name not in left.model)
    else:
        result, after_um = None, _screened_residual(measurement, left, effect)
        extra = len(effect.parameters)
    return float(after_um @ after_um), (_extra_test(measurement, left, after_um, extra), effect,
                                        result)


def _extra_test(measurement, left, after_um, extra):
    """The measurement's extra-sum-of-squares test of ``extra`` parameters leaving
    ``after_um`` on top of ``left``."""
    return measurement.noise.extra_ss_test(left.residual_um, after_um, extra,
                                           left.statistics.n_free + extra)


def _score_screens(measurement, left, effect, joined):
    """Whether ``effect`` is screened by its score test before its fit: it says so
    (``Effect.score_screened``), it joins ``left`` alone (no effect fitted beside it, whose
    start would be far from its fit) and the measurement has its exact sensitivities."""
    return (effect.score_screened and joined.names == (left.model + effect).names
            and measurement.sensitivity(joined) is not None)


def _screen_together(measurement, left, pending):
    """The sensitivities of every effect of ``pending`` that :func:`_tried` screens by its
    score test on top of ``left``, from one pass of the measurement (which keeps it): each
    screen's step starts from the effect's neutral values, which switch it off, so the
    system is the same for all and each screen takes its columns from that pass (on a
    500 s servo trace the Coulomb and Stribeck screens cost 0.55 s as two passes, 0.42 s
    as one)."""
    screened = [e for e in pending.values()
                if _score_screens(measurement, left, e, _joined(left.model, e, pending))]
    if len(screened) < 2:
        return
    model = left.model
    for effect in screened:
        model = model + effect
    start = {**left.model.values, **{e.name: measurement.neutral(e) for e in screened}}
    measurement.sensitivity(model)(start, [(e.name, p.name) for e in screened
                                           for p in e.parameters])


def _without_idle_companions(measurement, left, effect, result, test, stages):
    """(``result``, ``test``), or without the effects fitted beside ``effect``
    (``Effect.fitted_with``) when they are not significant on top of ``effect`` alone (the
    extra-sum-of-squares test at the policy's level; the test is then ``effect``'s alone):
    they were fitted beside it to let it show, and are named only when the data need them
    too."""
    companions = [e for e in result.model.effects
                  if e.name in effect.fitted_with and e.name not in left.model]
    if not companions:
        return result, test
    alone = fit(left.model + effect, measurement)
    extra = sum(len(e.parameters) for e in companions)
    needed = measurement.noise.extra_ss_test(alone.residual_um, result.residual_um, extra,
                                             result.statistics.n_free)
    if accepts(needed.p_value, len(companions), stages):
        return result, test
    return alone, measurement.noise.extra_ss_test(left.residual_um, alone.residual_um,
                                                  len(effect.parameters),
                                                  alone.statistics.n_free)


def _joined(model, effect, pending):
    """``model`` + ``effect``, with the effects it is fitted with (``Effect.fitted_with``)
    that the model lacks and the selection still tries: an effect that only shows with
    another refitted beside it (a friction the starting plant absorbed) is tested with it,
    the extra-sum-of-squares test counting both."""
    joined = model
    for name in effect.fitted_with:
        if name not in model and name in pending:
            joined = joined + pending[name]
    return joined + effect


def _screened_residual(measurement, left, effect, exact=False):
    """The residual of ``left`` after one Gauss-Newton step with ``effect`` added at its
    neutral values (the score test's linearisation): the step over the model's Jacobian
    at its optimum and the effect's columns by differences (its ``probe`` steps, else
    relative ones), or with ``exact`` from the measurement's sensitivities (one pass). An
    effect acting inside the system costs a simulation per parameter so, not a fit (on a
    500 s trace a fit of the loop took seconds); the effect the screening ranks first is
    then fitted in full and tested again."""
    model = left.model + effect
    start = {**left.model.values, effect.name: measurement.neutral(effect)}
    problem = Problem(model, [measurement])
    if exact:
        slots = [(effect.name, parameter.name) for parameter in effect.parameters]
        columns = list(measurement.sensitivity(model)(start, slots)[1].T)
        base_um = problem.predicted_um(start)
    else:
        base_um = problem.predicted_um(start)
        columns = _difference_columns(problem, effect, start, base_um)
    jacobian = left.jacobian if left.jacobian is not None else Problem(
        left.model, [measurement]).jacobian(ParameterLayout(left.model, measurement.case.axis))(
        ParameterLayout(left.model, measurement.case.axis).start())
    residual = measurement.measured_um - base_um
    return residual - projection(_design(jacobian, columns), residual)


def _design(jacobian, columns):
    """[−``jacobian`` | ``columns``] stored column by column (Fortran order), as LAPACK
    takes it: :func:`~feedaxis.stats.linear.projection` copies each block of its rows so
    without a strided pass over them for each column."""
    design = np.empty((jacobian.shape[0], jacobian.shape[1] + len(columns)), order="F")
    np.negative(jacobian, out=design[:, :jacobian.shape[1]])  # no negated copy beside it
    for at, column in enumerate(columns, start=jacobian.shape[1]):
        design[:, at] = column
    return design


def _difference_columns(problem, effect, start, base_um):
    """d prediction / d ``effect``'s parameters at ``start`` by forward differences (its
    ``probe`` steps, else relative ones)."""
    columns = []
    for parameter in effect.parameters:
        value = start[effect.name][parameter.name]
        step = effect.probe.get(parameter.name) or FD_STEP * max(1.0, abs(value))
        shifted = {**start, effect.name: {**start[effect.name], parameter.name: value + step}}
        columns.append((problem.predicted_um(shifted) - base_um) / step)
    return columns


def _best_candidate(measurement, left, tested, pending, skipped, stages):
    """The (test, effect, result) with the smallest p-value that passes the policy and is
    what the data show (a rival shape passes it over, with the reason), or None. A
    screened candidate (no result yet) is fitted in full and takes its place again by the
    full fit's test (a linearised step may promise more than the fit gives)."""
    tries = len(tested)
    tested = list(tested)
    while tested:
        tested.sort(key=lambda item: item[0].p_value)
        test, effect, result = tested[0]
        if result is None:
            if not accepts(test.p_value, tries, stages):
                return None
            result = fit(left.model + effect, measurement)
            test = measurement.noise.extra_ss_test(left.residual_um, result.residual_um,
                                                   len(effect.parameters),
                                                   result.statistics.n_free)
            tested[0] = (test, effect, result)
            continue
        if not accepts(test.p_value, tries, stages) or \
                _explained_um(left, result) < RESOLUTION_UM:
            return None
        rival = measurement.rival(effect, left, result)
        if rival is None:
            return test, effect, result
        skipped[effect.name] = rival
        del pending[effect.name]
        tested.pop(0)
    return None


def _withdraw(measurement, candidates, left, pending, skipped):
    """(candidates, fit) without the effects the selection's final fit ``left`` shows not
    to be what the data show (:meth:`~feedaxis.measurement.Measurement.withdrawn`), passed
    over with the reason and pending again (a record beside the deviation may still show
    them); the fit refitted with the nuisance columns given in their place."""
    withdrawn = measurement.withdrawn(left)
    if not withdrawn:
        return candidates, left
    model = Model([e for e in left.model.effects if e.name not in withdrawn], left.model.values)
    for name, (reason, columns) in withdrawn.items():
        skipped[name] = reason
        pending[name] = left.model.effects[left.model.names.index(name)]
        if columns is not None:
            model = model + BasisEffect(f"in_place_of_{name}", columns)
    left = _fit(model, measurement)
    return [c for c in candidates if c.effect not in withdrawn], left


def _candidate(measurement, left, effect, result, test):
    """The named effect, its result's model without nuisances (so it can be used as is)."""
    scale = measurement.noise.error_scale(result)
    clean = [e for e in result.model.effects if not isinstance(e, BasisEffect)]
    if len(clean) < len(result.model.effects):
        values = {e.name: result.model.values[e.name] for e in clean}
        result = replace(result, model=Model(clean, values))
    contribution = measurement.components(result.model)[effect.name]
    evidence = effect.evidence(measurement.case, result.model.values[effect.name], contribution)
    return Candidate(effect.name, result.rms_um,
                     float(result.statistics.bic - left.statistics.bic), test,
                     f"{evidence} ({test.describe()})", effect.meaning, result, scale)


def _recorded(measurement, left, pending, stages):
    """(candidates, fit) for the effects a record beside the deviation shows
    (:meth:`~feedaxis.measurement.Measurement.recorded_findings`): each joins the model
    at the values that record gives (the deviation does not move them), with their
    standard uncertainties."""
    candidates = []
    for effect, values, sigma, test, evidence in measurement.recorded_findings(left, pending,
                                                                               stages):
        model = left.model + effect
        left = replace(left, model=model.with_values({**model.values, effect.name: values}),
                       uncertainties={**left.uncertainties, effect.name: sigma})
        clean = [e for e in left.model.effects if not isinstance(e, BasisEffect)]
        result = replace(left, model=Model(clean, {e.name: left.model.values[e.name]
                                                   for e in clean}))
        candidates.append(Candidate(effect.name, left.rms_um, 0.0, test,
                                    f"{evidence} ({test.describe()})", effect.meaning, result))
        del pending[effect.name]
    return candidates, left


def _final_sizes(measurement, candidate, left):
    """``candidate`` with its sizes and evidence from the last fit of the selection, where
    every effect named was refitted with those named after it (an effect named early, on a
    model still missing another, is sized by the joint fit)."""
    if candidate.effect not in left.model or candidate.result is left:
        return candidate
    clean = [e for e in left.model.effects if not isinstance(e, BasisEffect)]
    values = {e.name: left.model.values[e.name] for e in clean}
    joint = replace(left, model=Model(clean, values))
    effect = clean[[e.name for e in clean].index(candidate.effect)]
    contribution = measurement.components(joint.model)[effect.name]
    evidence = effect.evidence(measurement.case, values[effect.name], contribution)
    return replace(candidate, joint=joint, error_scale=measurement.noise.error_scale(left),
                   evidence=f"{evidence} ({candidate.test.describe()})")


def _nuisance_findings(measurement, left, stages, notify):
    """Each nuisance in the final model, reported when its test against the fit without it
    passes (the model's fit before the nuisances were added, where that is the one)."""
    found = []
    for name, shape, _ in measurement.nuisances():
        if name not in left.model:
            continue
        notify(name)
        test = nuisance_test(measurement, left, name, shape.extra)
        if not accepts(test.p_value, 1, stages):
            continue
        nuisance = left.model.effects[left.model.names.index(name)]
        fitted = nuisance.prepare(measurement.case)(left.model.values[name])
        trial = shape.trial(measurement, left)
        found.append(Structure(shape.kind, measurement.location_key, None,
                               shape.amplitude_um(measurement, fitted, None), test,
                               f"{shape.describe(measurement, trial, fitted)} "
                               f"({test.describe()})", fitted, nuisance.basis))
    return found


def nuisance_test(measurement, left, name, extra):
    """The extra-sum-of-squares test of the nuisance ``name`` (``extra`` columns) in the
    fit ``left`` against the same model refitted without it (the fit before the nuisances
    were added, where that is the one)."""
    nuisance = left.model.effects[left.model.names.index(name)]
    others = Model([e for e in left.model.effects if e is not nuisance], left.model.values)
    without = (left.plain if left.plain is not None and left.plain.model.names == others.names
               else _fit(others, measurement))
    return measurement.noise.extra_ss_test(without.residual_um, left.residual_um, extra,
                                           left.statistics.n_free)


def find_structures(measurement, left, shapes, stages, notify=None):
    """(structures, final fit): structure in the residual of ``left`` that no effect
    explains, strongest first.

    At each step every shape is fitted to the residual and tested; the best is accepted by
    the family-wise policy with Bonferroni over all shapes tried (a free-frequency search
    counts every resolvable frequency), added to the model as a linear basis, the model
    refitted and the search repeated (a shape with a location may be found again
    elsewhere); a shape marked ``last`` ends the search. Then the measurement's test for an
    irregular lack of fit.
    """
    structures, current, shapes = [], left, list(shapes)
    for _ in range(MAX_STRUCTURES):
        best = _best_shape(measurement, current, shapes, stages)
        if best is None or not accepts(best[0].p_value, best[-1], stages):
            break
        test, shape, trial, fitted, amplitude_um, _ = best
        structures.append(Structure(shape.kind, measurement.location_key, trial.location,
                                    amplitude_um, test,
                                    f"{shape.describe(measurement, trial, fitted)} "
                                    f"({test.describe()})", fitted, trial.basis,
                                    dict(trial.extra or {})))
        if getattr(shape, "last", False):
            return structures, current
        if trial.location is None:
            shapes.remove(shape)
        model = current.model + BasisEffect(f"structure_{len(structures)}", trial.basis)
        if too_few_samples(model, [measurement]):
            break
        if notify:
            notify("structures")
        current = fit(model, measurement)
    irregular = measurement.irregular(current)
    if irregular:
        kind, test, fitted, what = irregular
        if accepts(test.p_value, 1, stages):
            structures.append(Structure(kind, measurement.location_key, None,
                                        float(np.ptp(fitted) / 2), test,
                                        f"{what} ({test.describe()})", fitted))
    return structures, current


def _best_shape(measurement, current, shapes, stages):
    """(test, shape, trial, fitted, amplitude, shapes tried) of the shape with the smallest
    p-value at the residual of ``current``, or None.

    A shape whose search test (``Shape.search_test``) fails the policy at ``stages`` even
    counted alone cannot be the one accepted, so it is not located: it is left out of the
    options, and only where the count of shapes tried then decides whether the best passes
    is its trial made, to count it as the full search does (a trial may come to None)."""
    residual, options, tried, deferred = current.residual_um, [], 0, []
    for shape in shapes:
        trials = shape.trials(measurement)
        if not trials:
            continue
        test = shape.search_test(measurement, current)
        if test is not None and not accepts(test.p_value, trials, stages):
            deferred.append((shape, trials))
            continue
        trial = shape.trial(measurement, current)
        if trial is None:
            continue
        tried += trials
        fitted = projection(trial.basis, residual)
        amplitude_um = shape.amplitude_um(measurement, fitted, trial.location)
        if amplitude_um < RESOLUTION_UM:
            continue
        test = trial.test or measurement.noise.shape_test(
            residual, residual - fitted, shape.extra, current.statistics.n_free + shape.extra)
        options.append((test, shape, trial, fitted, amplitude_um))
    if not options:
        return None
    best = min(options, key=lambda option: option[0].p_value)
    passes = accepts(best[0].p_value, tried, stages)
    if passes != accepts(best[0].p_value, tried + sum(t for _, t in deferred), stages):
        tried += sum(trials for shape, trials in deferred
                     if shape.trial(measurement, current) is not None)
    return (*best, tried)
