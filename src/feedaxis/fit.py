"""One fit engine for every kind of measurement: bounded least squares over a model's
effects, on one or several cases jointly.

The measurement (:mod:`feedaxis.measurement`) says how a model predicts the samples; the
engine never knows what made the residual, as lmfit's minimiser never knows its model.
Where parameters enter linearly (``Effect.linear``), variable projection solves for them
exactly by bounded linear least squares at every step of the optimiser over the others,
and their Jacobian columns are the projection's columns, not finite differences. Where the
prediction is not separable (the closed loop of a tracking case), the optimiser moves every
parameter from a probed start. One :class:`FitResult` carries the fitted model, the
residual and its statistics (RMS, max, P-V, R², AIC, BIC) and each parameter's standard
uncertainty, widened where the measurement's residual is serially correlated.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
from scipy.optimize import least_squares, lsq_linear

from .effects import BasisEffect, FitRecord, Model
from .errors import InputError
from .measurement import Measurement, kinds_for, measurement_of
from .physics.threads import one_blas_thread
from .stats.linear import normal_solve, subtract_product, unit_gram

SINGULAR_RATIO = 1e-6
# Residual degrees of freedom a fit must leave for the noise: with nu of them the noise
# estimate s has a relative standard error of about 1/sqrt(2 nu) (chi-square with nu degrees
# of freedom), 25 % at nu = 8; with fewer, BIC and the noise-based verdicts mean nothing.
NOISE_DOF = 8
FD_STEP = np.sqrt(np.finfo(float).eps)  # relative step of the finite differences
MAX_NFEV_PER_PARAMETER = 100  # a trust-region pass's evaluations per parameter it moves


@dataclass(frozen=True)
class Statistics:
    """Residual figures of a model on measured data (µm); AIC/BIC for Gaussian errors."""

    n_points: int
    n_free: int
    rms_before_um: float
    rms_um: float
    max_um: float
    pv_um: float
    r2: float
    aic: float
    bic: float

    @classmethod
    def of(cls, measured_um, residual_um, n_free):
        n = measured_um.size
        rss = max(float(residual_um @ residual_um), 1e-300)
        tss = float(np.sum((measured_um - measured_um.mean()) ** 2))
        log_likelihood_term = n * np.log(rss / n)
        return cls(n, n_free, rms(measured_um), rms(residual_um),
                   float(np.max(np.abs(residual_um))), float(np.ptp(residual_um)),
                   1.0 - rss / tss if tss > 0 else float("nan"),
                   log_likelihood_term + 2 * n_free, log_likelihood_term + n_free * np.log(n))


def rms(values):
    """Root mean square of ``values``."""
    return float(np.sqrt(np.mean(np.square(values))))


@dataclass
class FitResult:
    """A fitted model with its residual, statistics and parameter uncertainties.

    ``measured_um`` is the measured deviation, ``residual_um`` measured - predicted, both
    at the samples of ``measurements`` concatenated; ``jacobian`` d residual / d parameters
    at the optimum (samples x parameters in the model's order), kept where the model has
    parameters that enter nonlinearly (for the diagnosis's linearised screening).
    ``plain`` is the fit of the same samples without the measurement's nuisances, where
    :func:`fit_with_artefacts` fitted them beside the effects (for their test: its residual
    and statistics alone, :meth:`Solved.bare`).
    """

    model: Model
    statistics: Statistics
    measured_um: np.ndarray
    residual_um: np.ndarray
    uncertainties: dict = field(default_factory=dict)
    undetermined: dict = field(default_factory=dict)
    covariance: np.ndarray | None = field(default=None, repr=False)
    measurements: list = field(default_factory=list, repr=False)
    artefacts: dict = field(default_factory=dict)
    jacobian: np.ndarray | None = field(default=None, repr=False)
    plain: FitResult | None = field(default=None, repr=False)

    @property
    def rms_um(self):
        return self.statistics.rms_um

    @property
    def kind(self):
        """The kind of measurement fitted (``"positioning"``, ``"tracking"``)."""
        return self.measurements[0].kind

    def params(self):
        """{effect: {parameter: value}} of the fitted model."""
        return {name: dict(self.model.values[name]) for name in self.model.names}

    def fitted_model(self):
        """The fitted model as ``fit --out`` saves it: its effects (the measurement
        artefacts fitted beside them, a drift, left out: they are not the machine's) with
        the :class:`~feedaxis.effects.FitRecord` of their covariance, the undetermined
        parameters and the artefacts."""
        kept = [e for e in self.model.effects if not isinstance(e, BasisEffect)]
        model = Model(kept, {e.name: self.model.values[e.name] for e in kept})
        keys, every = model.parameter_keys, self.model.parameter_keys
        index = [every.index(key) for key in keys]
        covariance = (self.covariance[np.ix_(index, index)] if self.covariance is not None
                      else np.zeros((len(keys),) * 2))
        nuisances = {e.name: dict(self.model.values[e.name]) for e in self.model.effects
                     if isinstance(e, BasisEffect)}
        artefacts = {**self.artefacts, **({"nuisances": nuisances} if nuisances else {})}
        return model.with_record(FitRecord(
            keys, covariance, {k: v for k, v in self.undetermined.items() if k in keys},
            self.statistics.n_points, self.rms_um, artefacts))


def measurements(model, data, kind=None):
    """The samples ``model`` is fitted to: ``data`` is a Case or Measurement or a list of
    either; cases give their samples of ``kind`` (default: the kind of the model's
    effects, or the one kind every case holds)."""
    items = list(data) if isinstance(data, (list, tuple)) else [data]
    if all(isinstance(item, Measurement) for item in items):
        return items
    if kind is None:
        kinds = kinds_for(items, model)
        if len(kinds) > 1:
            raise InputError(f"the cases hold {' and '.join(kinds)} samples and the model "
                             "names no kind; choose one", path=items[0].folder)
        kind = kinds[0]
    return [measurement_of(case, kind) for case in items]


def check_available(model, data, kind=None):
    """The measurements of ``data`` for ``model``; :class:`InputError` when an effect cannot
    act on them, when cases fitted jointly describe different axes, or when the samples
    are too few to fit. Nothing is fitted."""
    found = measurements(model, data, kind)
    first = found[0].case.axis
    for measurement in found[1:]:
        axis = measurement.case.axis
        if (axis.screw, axis.motor, axis.servo) != (first.screw, first.motor, first.servo):
            raise InputError(f"axis.toml differs from {found[0].case.folder}; cases fitted "
                             "together must describe the same axis", path=measurement.case.folder)
    for measurement in found:
        measurement.check(model)
    shortfall = too_few_samples(model, found)
    if shortfall:
        raise InputError(shortfall, path=found[0].path)
    return found


def too_few_samples(model, found):
    """Why the samples of ``found`` (measurements) cannot support a fit of ``model``
    (None if they can): it needs one sample per parameter plus :data:`NOISE_DOF` for the
    noise, and samples the measurement can fit at all (two targets, say)."""
    n_samples = sum(m.size for m in found)
    n_parameters = sum(len(effect.parameters) for effect in model.effects)
    needed = n_parameters + NOISE_DOF
    if n_samples < needed:
        return (f"{n_samples} samples; a fit of {' + '.join(model.names) or 'the empty model'} "
                f"needs at least {needed} "
                f"({n_parameters} parameters + {NOISE_DOF} degrees of freedom for the noise)")
    reasons = [m.degenerate() for m in found]
    return None if any(r is None for r in reasons) else reasons[0]


def evaluate(model, data, kind=None):
    """Statistics and residual of ``model`` as it stands (no fitting)."""
    found = check_available(model, data, kind)
    for measurement in found:
        measurement.check_start(model, model.values)
    problem = Problem(model, found)
    residual = problem.measured_um - problem.predicted_um(model.values)
    return FitResult(model, Statistics.of(problem.measured_um, residual, 0),
                     problem.measured_um, residual, measurements=found,
                     jacobian=np.zeros((residual.size, 0)))


@one_blas_thread
def fit(model, data, progress=None, kind=None):
    """Fit every parameter of ``model`` to ``data`` by bounded least squares.

    Effects without values start from their :meth:`~feedaxis.effects.Effect.guess` on the
    residual of the effects before them, then a linearised step for probed ones. Variable
    projection finds the optimum over the nonlinear parameters with the linear ones solved
    exactly; a trust-region pass over all parameters then confirms it and gives the
    Jacobian for the uncertainties.

    Parameters
    ----------
    model : Model
    data : Case, Measurement or list of them
        Fitted jointly; their residuals are concatenated.
    progress : callable, optional
        Called once per model evaluation (for a progress bar), and first as
        ``progress(total=N)`` with the most evaluations the fit can make
        (:func:`evaluation_bound`).
    kind : str, optional
        The kind of measurement, where the model names none and a case holds several.

    Returns
    -------
    FitResult
    """
    return _solved(model, check_available(model, data, kind), progress).analysed()


def _solved(model, found, progress=None):
    """The optimum of ``model`` on the measurements ``found`` (:func:`fit`'s search), not
    yet analysed: :meth:`Solved.analysed` gives the fit, :meth:`Solved.bare` its residual
    alone."""
    model = starting_values(model, found)
    layout = ParameterLayout(model, found[0].case.axis)
    if layout.size == 0:
        return Solved(model, found, None, layout, None)
    problem = Problem(model, found, progress)
    if progress:
        progress(total=evaluation_bound(layout))
    with np.errstate(over="ignore"):  # a trial step may overflow; the optimiser steps back
        start = variable_projection(problem, layout)
        solution = (_linear_solution(problem, layout, start)
                    if layout.nonlinear_index.size == 0
                    else least_squares(problem.residual(layout), start, bounds=layout.bounds(),
                                       jac=problem.jacobian(layout), x_scale="jac",
                                       method="trf",
                                       max_nfev=MAX_NFEV_PER_PARAMETER * layout.size))
    return Solved(model, found, problem, layout, solution)


@dataclass
class Solved:
    """:func:`fit`'s optimum (``solution`` as SciPy's least_squares gives it; None where the
    model has no parameter) before its uncertainties are worked out."""

    model: Model
    found: list
    problem: Problem
    layout: ParameterLayout
    solution: object

    def analysed(self):
        """The :class:`FitResult` with the parameters' uncertainties, what the data leave
        undetermined and the Jacobian."""
        if self.solution is None:
            return evaluate(self.model, self.found)
        layout, solution, found = self.layout, self.solution, self.found
        sigma, undetermined, covariance = uncertainties(solution.jac, solution.fun,
                                                        solution.active_mask, layout, found)
        fitted = self.fitted_model()
        if found[0].loose_share is not None:
            flag_loose(fitted, sigma, undetermined, found[0].loose_share, found[0].excitation)
        if len(found) == 1:
            for key, reason in {**unresolved_terms(fitted, found[0]), **found[0].confounded(
                    fitted, layout.slots, solution.jac, solution.fun, sigma)}.items():
                undetermined.setdefault(key, reason)
        result = FitResult(fitted, self._statistics(), self.problem.measured_um,
                           solution.fun, sigma, undetermined, covariance, found,
                           jacobian=solution.jac if layout.nonlinear_index.size else None)
        _check_finite(result, found)
        return result

    def bare(self):
        """The :class:`FitResult` with its residual and statistics alone (a fit kept only to
        be tested against, as the one before a measurement's nuisances: at 500,000 samples
        the uncertainties' analysis costs tens of milliseconds)."""
        if self.solution is None:
            return evaluate(self.model, self.found)
        result = FitResult(self.fitted_model(), self._statistics(), self.problem.measured_um,
                           self.solution.fun, measurements=self.found)
        _check_finite(result, self.found)
        return result

    def fitted_model(self):
        return self.model.with_values(self.layout.values(self.solution.x))

    def _statistics(self):
        return Statistics.of(self.problem.measured_um, self.solution.fun, self.layout.size)


def unresolved_terms(model, measurement):
    """{"effect.parameter": why} of the model's effects whose wavelength the samples cannot
    resolve (``measurement.unresolvable``, the rule by which diagnose passes them over and
    comp-table leaves them out): fitted when asked for, but undetermined."""
    return {f"{effect.name}.{parameter.name}": f"the targets cannot resolve it: {reason}"
            for effect in model.effects
            if (reason := measurement.unresolvable(effect))
            for parameter in effect.parameters}


@one_blas_thread
def fit_with_artefacts(model, data, progress=None, kind=None):
    """:func:`fit` with what the measurement says about its own samples fitted too, as the
    diagnosis does: its outliers kept out (refitted without them), its nuisances (a drift
    along a positioning test's clock) fitted beside the effects as measurement artefacts.
    ``artefacts`` lists the outlier and transient rows and the nuisances; the measurement
    fitted is ``result.measurements[0]``. Cases fitted jointly get the plain fit."""
    found = check_available(model, data, kind)
    if len(found) > 1:
        return fit(model, found, progress)
    measurement = found[0]
    solved = _solved(model, found, progress)
    plain = solved.bare()  # analysed only where it is the result
    outliers = measurement.outliers(plain.residual_um)
    transients = measurement.transients(outliers)
    artefacts = {"outlier_rows": measurement.rows(np.setdiff1d(outliers, transients)),
                 "transient_rows": measurement.rows(transients)}
    if outliers.size:
        keep = np.ones(measurement.size, dtype=bool)
        keep[outliers] = False
        measurement = measurement.subset(keep)
        solved = _solved(plain.model, [measurement], progress)  # starts where the last ended
        plain = solved.bare()
    with_nuisances = plain.model
    for name, _, basis in measurement.nuisances():
        with_nuisances = with_nuisances + BasisEffect(name, basis)
    if with_nuisances is not plain.model and not too_few_samples(with_nuisances,
                                                                  [measurement]):
        result = fit(with_nuisances, measurement, progress)
        result.plain = plain  # only its residual is used again (the nuisances' test)
    else:
        result = solved.analysed()
    result.artefacts = {**artefacts, **measurement.artefacts(result)}
    return result


class Problem:
    """The measurements fitted jointly and the model's prediction of them.

    The separable split (base and linear columns) at the last parameter vector is kept, so
    the optimiser's residual and Jacobian at one point cost one evaluation.
    """

    def __init__(self, model, found, progress=None):
        self.model, self.found, self.progress = model, found, progress
        self.measured_um = (found[0].measured_um if len(found) == 1   # no copy per fit
                            else np.concatenate([m.measured_um for m in found]))
        self.separators = [m.separable(model) for m in found]
        self.sensitivities = [m.sensitivity(model) for m in found]
        self._last = (None, None)

    def exact(self, layout):
        """Whether every nonlinear parameter's column comes from the measurements'
        sensitivities: each has them and those parameters all act in its core (an additive
        effect's nonlinear parameters move its columns, which they do not cover)."""
        additive = {e.name for e in self.model.effects if e.additive}
        return (all(s is not None for s in self.sensitivities)
                and not any(layout.slots[i][0] in additive for i in layout.nonlinear_index))

    def core_derivatives(self, layout, x):
        """d base_um / d the nonlinear parameters (samples x their count) at ``x``, from
        one sensitivity pass of each measurement."""
        if self.progress:
            self.progress()
        slots = [layout.slots[i] for i in layout.nonlinear_index]
        values = layout.values(x)
        parts = [sensitivity(values, slots)[1] for sensitivity in self.sensitivities]
        return parts[0] if len(parts) == 1 else np.vstack(parts)

    def predicted_um(self, values):
        base_um, columns_um = self.split(values)
        linear = [values[e.name][p] for e in self.model.effects for p in e.linear]
        return base_um + columns_um @ np.array(linear, dtype=float)

    def split(self, values):
        """(base_um, columns_um) of every measurement, concatenated."""
        if self.progress:
            self.progress()
        parts = [separate(values) for separate in self.separators]
        if len(parts) == 1:
            return parts[0]
        return (np.concatenate([base for base, _ in parts]),
                np.vstack([columns for _, columns in parts]))

    def _split_at(self, layout, x):
        """:meth:`split` at ``x``, kept for the next call at the same nonlinear parameters
        (the split ignores the linear ones)."""
        key = x[layout.nonlinear_index].tobytes()
        if self._last[0] != key:
            self._last = (key, self.split(layout.values(x)))
        return self._last[1]

    def residual(self, layout):
        """``f(x) -> measured - predicted`` over the layout's parameter vector."""
        def residual(x):
            base_um, columns_um = self._split_at(layout, x)
            return subtract_product(self.measured_um - base_um, columns_um,
                                    x[layout.linear_index])
        return residual

    def linear_jacobian(self, layout, x):
        """d residual / dx at ``x`` of a model whose parameters all enter linearly: its
        columns negated in place (the split kept at ``x`` is dropped, so no second samples x
        parameters array is made)."""
        _, columns_um = self._split_at(layout, x)
        self._last = (None, None)
        return np.negative(columns_um, out=columns_um)

    def jacobian(self, layout):
        """``f(x) -> d residual / dx``: the linear parameters' columns exactly, the others
        from the sensitivities (:meth:`exact`), else by forward differences stepped into the
        bounds; stored column by column (Fortran order) like the sensitivities, as SciPy's
        trust region scales and sums it."""
        nonlinear = layout.nonlinear_index
        exact = self.exact(layout)

        def jacobian(x):
            base_um, columns_um = self._split_at(layout, x)
            if exact and nonlinear.size == layout.size:  # the derivatives are the matrix
                derivatives = self.core_derivatives(layout, x)  # an array of its own
                return np.negative(derivatives, out=derivatives)
            matrix = np.empty((base_um.size, layout.size), order="F")
            matrix[:, layout.linear_index] = columns_um
            if exact and nonlinear.size:
                matrix[:, nonlinear] = self.core_derivatives(layout, x)
                return np.negative(matrix, out=matrix)  # no negated copy of either part
            np.negative(matrix, out=matrix)
            here_um = base_um + columns_um @ x[layout.linear_index]
            for index in nonlinear:
                step = FD_STEP * max(1.0, abs(x[index]))
                if x[index] + step > layout.upper[index]:
                    step = -step
                moved = x.copy()
                moved[index] += step
                moved_base_um, moved_columns_um = self.split(layout.values(moved))
                moved_um = moved_base_um + moved_columns_um @ moved[layout.linear_index]
                matrix[:, index] = -(moved_um - here_um) / step
            return matrix

        return jacobian


class ParameterLayout:
    """Where each effect's parameters sit in the flat vector the optimiser moves."""

    def __init__(self, model, axis):
        self.model = model
        self.slots = [(e.name, p.name) for e in model.effects for p in e.parameters]
        self.linear_index = np.array([self.slots.index((e.name, name)) for e in model.effects
                                      for name in e.linear], dtype=int)
        self.nonlinear_index = np.setdiff1d(np.arange(len(self.slots)), self.linear_index)
        limits = {e.name: e.bounds(axis) for e in model.effects}
        self.lower = np.array([limits[e][p][0] for e, p in self.slots], dtype=float)
        self.upper = np.array([limits[e][p][1] for e, p in self.slots], dtype=float)

    @property
    def size(self):
        return len(self.slots)

    def start(self):
        """The model's values as a vector, just inside the bounds."""
        x0 = np.array([self.model.values[e][p] for e, p in self.slots], dtype=float)
        margin = 1e-9 * (self.upper - self.lower)
        return np.clip(x0, self.lower + margin, self.upper - margin)

    def bounds(self):
        return self.lower, self.upper

    def values(self, x):
        values = {name: {} for name in self.model.names}
        for (effect_name, parameter_name), value in zip(self.slots, x):
            values[effect_name][parameter_name] = float(value)
        return values


def variable_projection(problem, layout):
    """Starting vector at the optimum over the nonlinear parameters, the linear ones
    (``Effect.linear``) solved exactly by bounded linear least squares at every step.

    Fewer parameters for the optimiser and no poor start for the linear ones; with no
    nonlinear parameter it is one linear solve, with no linear one the start itself.
    """
    lower, upper = layout.bounds()
    linear, nonlinear = layout.linear_index, layout.nonlinear_index
    x = layout.start()
    if linear.size == 0:
        return x

    last = {}

    def project(x_nonlinear):
        x[nonlinear] = x_nonlinear
        base_um, columns_um = problem._split_at(layout, x)
        target_um = problem.measured_um - base_um
        x[linear] = bounded_linear_solve(columns_um, target_um, lower[linear], upper[linear])
        last.update(columns_um=columns_um, free=(x[linear] > lower[linear])
                    & (x[linear] < upper[linear]))
        return subtract_product(target_um, columns_um, x[linear])

    def projected_jacobian(x_nonlinear):
        """d project / d x_nonlinear with the columns fixed (they are where
        :meth:`Problem.exact` holds): −(I − C_f C_f⁺)·d base / dθ, C_f the columns of the
        linear parameters inside their bounds (those at a bound stay there)."""
        if not np.array_equal(x[nonlinear], x_nonlinear):
            project(x_nonlinear)
        derivatives = problem.core_derivatives(layout, x)  # an array of its own
        free = last["columns_um"][:, last["free"]]
        if free.shape[1]:
            derivatives -= free @ np.linalg.lstsq(free, derivatives, rcond=None)[0]
        return np.negative(derivatives, out=derivatives)

    if nonlinear.size:
        solution = least_squares(project, x[nonlinear], bounds=(lower[nonlinear],
                                                                upper[nonlinear]),
                                 jac=projected_jacobian if problem.exact(layout) else "2-point",
                                 x_scale="jac", method="trf",
                                 max_nfev=MAX_NFEV_PER_PARAMETER * nonlinear.size)
        project(solution.x)
    else:
        project(x[nonlinear])
    margin = 1e-9 * (upper - lower)
    return np.clip(x, lower + margin, upper - margin)


def evaluation_bound(layout):
    """The most model evaluations one :func:`fit` over ``layout`` makes: each of its two
    trust-region passes (the projection's over the nonlinear parameters, the polish over
    all) stops after ``MAX_NFEV_PER_PARAMETER`` evaluations per parameter it moves (SciPy's
    default for TRF, passed explicitly), each followed by at most one forward-difference
    Jacobian of one evaluation per nonlinear parameter; plus the projection's last."""
    per_step = 1 + layout.nonlinear_index.size
    moved = layout.nonlinear_index.size + (layout.size if layout.nonlinear_index.size else 0)
    return MAX_NFEV_PER_PARAMETER * moved * per_step + 2


def bounded_linear_solve(columns, target, lower, upper):
    """Least-squares coefficients of ``columns`` (samples x k) for ``target`` within the
    bounds: the normal equations of the unit-scaled columns (a k x k solve, minimum norm
    where the columns are dependent) when that solution is inside the bounds, else
    bounded-variable least squares (scipy's BVLS)."""
    free = normal_solve(columns, target)
    if np.all((free >= lower) & (free <= upper)):
        return free
    scale = unit_gram(columns)[1]
    solution = lsq_linear(columns / scale, target, method="bvls",
                          bounds=(lower * scale, upper * scale))
    return np.clip(solution.x / scale, lower, upper)


def _linear_solution(problem, layout, x):
    """The optimum of a model whose parameters all enter linearly: the projection's bounded
    linear solve is exact, so its residual, Jacobian (the columns) and active bounds stand
    for the trust-region pass (which on 10^6 samples cost seconds per iteration)."""
    lower, upper = layout.bounds()
    margin = 2e-9 * (upper - lower)
    active = np.where(x <= lower + margin, -1, np.where(x >= upper - margin, 1, 0))
    return SimpleNamespace(x=x, fun=problem.residual(layout)(x),
                           jac=problem.linear_jacobian(layout, x), active_mask=active)


def starting_values(model, found):
    """Give each effect lacking values its guess on the residual of the effects before it
    (additive effects), then one linearised least-squares step for the probed parameters
    of effects still at their neutral values (``Effect.probe``)."""
    case = found[0].case
    running = np.array(found[0].measured_um, dtype=float)
    values = {}
    for effect in model.effects:
        current = model.values[effect.name]
        if not current and effect.parameters:
            limits = effect.bounds(case.axis)
            current = {name: float(np.clip(value, *limits[name]))
                       for name, value in effect.guess(case, running).items()}
        values[effect.name] = current
        if effect.additive:
            running = running - effect.prepare(case)(current)
    model = model.with_values(values)
    for measurement in found:
        measurement.check_start(model, model.values)
    probed = [(e, name, step) for e in model.effects if not any(model.values[e.name].values())
              for name, step in e.probe.items()]
    return _probed_step(model, found, probed) if probed else model


def _probed_step(model, found, probed):
    """One linearised least-squares step of the ``probed`` (effect, parameter, step)."""
    problem = Problem(model, found)
    base_um = problem.predicted_um(model.values)
    columns = []
    for effect, name, step in probed:
        shifted = {**model.values, effect.name: {**model.values[effect.name], name: step}}
        columns.append((problem.predicted_um(shifted) - base_um) / step)
    steps = np.linalg.lstsq(np.column_stack(columns), problem.measured_um - base_um,
                            rcond=None)[0]
    values = {name: dict(v) for name, v in model.values.items()}
    for (effect, name, _), value in zip(probed, steps):
        lower, upper = effect.bounds(found[0].case.axis)[name]
        values[effect.name][name] = float(np.clip(value, lower, upper))
    return model.with_values(values)


def uncertainties(jacobian, residual, active_mask, layout, found):
    """(standard uncertainties, undetermined parameters, covariance) from the Jacobian at
    the optimum, the covariance in the order of ``layout.slots``: the sandwich
    (J'J)⁺ J'ΣJ (J'J)⁺ with each measurement's J'ΣJ for the noise its residual shows
    (:meth:`~feedaxis.measurement.Measurement.noise_gram`: σ² J'J for white noise, which
    gives the usual σ² (J'J)⁺).

    A parameter is undetermined when :func:`inseparable` finds it in a (nearly) singular
    direction of the Jacobian, when its standard uncertainty exceeds the whole range its
    bounds allow (a column of rounding noise, as the sine of a once-per-revolution error at
    targets that are all whole leads, escapes the singular-direction test once scaled to
    unit length), or when it ends on a bound.
    """
    variance = float(residual @ residual) / max(residual.size - layout.size, 1)
    scale, singular, vt, strong = _unit_column_svd(jacobian)
    inverse = (vt[strong].T / singular[strong] ** 2) @ vt[strong]
    bounds = np.cumsum([0] + [m.size for m in found])
    unit = np.outer(scale, scale)  # J'ΣJ is bilinear: that of the unit columns, without them
    gram = sum(m.noise_gram(jacobian[start:stop], residual[start:stop], variance)
               for m, start, stop in zip(found, bounds[:-1], bounds[1:])) / unit
    covariance = inverse @ gram @ inverse / unit
    keys = [f"{effect_name}.{parameter_name}" for effect_name, parameter_name in layout.slots]
    undetermined = _inseparable(vt, strong, keys)
    sigma = {name: {} for name in layout.model.names}
    for index, (effect_name, parameter_name) in enumerate(layout.slots):
        key = keys[index]
        sigma[effect_name][parameter_name] = float(np.sqrt(max(covariance[index, index], 0.0)))
        if key in undetermined:
            sigma[effect_name][parameter_name] = float("nan")
        elif sigma[effect_name][parameter_name] > layout.upper[index] - layout.lower[index]:
            undetermined[key] = ("the data do not determine it: its standard uncertainty "
                                 "exceeds the whole range of its bounds")
        elif active_mask[index] != 0:
            undetermined[key] = "ended on its bound"
    return sigma, undetermined, covariance


def inseparable(jacobian, keys):
    """{key: why} of the parameters (the columns of ``jacobian``, named by ``keys``) that
    the data cannot determine at this point: with a share over 0.1 in a (nearly) singular
    direction of the Jacobian with its columns scaled to unit length (singular value below
    ``SINGULAR_RATIO`` of the largest), so units do not matter."""
    _, _, vt, strong = _unit_column_svd(np.asarray(jacobian, dtype=float))
    return _inseparable(vt, strong, list(keys))


def _unit_column_svd(jacobian):
    """(column norms, singular values, right singular vectors, strong mask) of
    ``jacobian`` with unit columns, from the eigen-decomposition of its Gram matrix (a
    parameters x parameters problem, where an SVD of samples x parameters costs seconds at
    10^6 samples; SINGULAR_RATIO squared stays far above the Gram matrix's rounding), scaled
    after the product and the norms from its diagonal (no scaled or squared copy of the
    Jacobian)."""
    gram, scale = unit_gram(jacobian)
    eigenvalues, vectors = np.linalg.eigh(gram)
    order = np.argsort(eigenvalues)[::-1]
    singular, vt = np.sqrt(np.maximum(eigenvalues[order], 0.0)), vectors[:, order].T
    strong = singular > SINGULAR_RATIO * max(singular[0] if singular.size else 0.0, 1e-300)
    return scale, singular, vt, strong


def _inseparable(vt, strong, keys):
    in_weak_direction = np.abs(vt[~strong]) > 0.1
    undetermined = {}
    for index, key in enumerate(keys):
        if in_weak_direction[:, index].any():
            partners = sorted({keys[j] for row in in_weak_direction if row[index]
                               for j in np.flatnonzero(row) if j != index})
            undetermined[key] = (f"the data cannot separate it from {', '.join(partners)}"
                                 if partners else "the data do not depend on it")
    return undetermined


def flag_loose(model, sigma, undetermined, share, excitation):
    """Add to ``undetermined`` the parameters whose standard uncertainty exceeds ``share``
    of their value: the data fix them only loosely; ``excitation()`` says what the data are
    (a single sine fixes only a loop's gain and phase at its frequency), asked only where a
    parameter is loose (on a long trace it costs a second)."""
    words = None
    for name in model.names:
        for parameter, value in model.values[name].items():
            key, spread = f"{name}.{parameter}", sigma[name][parameter]
            if key not in undetermined and spread > share * abs(value):
                words = excitation() if words is None else words
                undetermined[key] = (
                    f"the data fix it only to ±{100 * spread / max(abs(value), 1e-300):.0f} %: "
                    f"{words}")


def _check_finite(result, found):
    """Raise :class:`InputError` unless the fitted values and residual are finite numbers."""
    values = [(f"{e}.{p}", v) for e, params in result.params().items() for p, v in params.items()]
    values.append(("the residual RMS", result.rms_um))
    bad = [name for name, value in values if not np.isfinite(value)]
    if bad:
        raise InputError(f"the fit gives no finite value for {', '.join(bad)}; nothing was "
                         "written (the data cannot determine the model)",
                         path=", ".join(str(m.case.folder) for m in found))
