"""Bounded least squares over a model's effects, on one or several cases jointly.

One :class:`FitResult` carries the fitted model, the residual and its statistics
(RMS, max, P-V, R², AIC, BIC) and each parameter's standard uncertainty.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares, lsq_linear
from threadpoolctl import threadpool_limits

from .effects import FitRecord, Model
from .errors import InputError

SINGULAR_RATIO = 1e-6
# Residual degrees of freedom a fit must leave for the noise: with nu of them the noise
# estimate s has a relative standard error of about 1/sqrt(2 nu) (chi-square with nu degrees
# of freedom), 25 % at nu = 8; with fewer, BIC and the noise-based verdicts mean nothing.
NOISE_DOF = 8
SAME_TARGET_MM = 1e-4  # targets closer than 0.1 µm are one target (recorded jitter)


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
    """A fitted model with its residual, statistics and parameter uncertainties."""

    model: Model
    statistics: Statistics
    measured_um: np.ndarray
    residual_um: np.ndarray
    uncertainties: dict = field(default_factory=dict)
    undetermined: dict = field(default_factory=dict)
    covariance: np.ndarray | None = field(default=None, repr=False)

    @property
    def rms_um(self):
        return self.statistics.rms_um

    def fitted_model(self):
        """The fitted model carrying its :class:`~feedaxis.effects.FitRecord` (covariance,
        undetermined parameters), as ``fit --out`` saves it."""
        keys = self.model.parameter_keys
        covariance = self.covariance if self.covariance is not None else np.zeros((len(keys),) * 2)
        return self.model.with_record(FitRecord(keys, covariance, dict(self.undetermined),
                                                self.statistics.n_points, self.rms_um))

    def params(self):
        """{effect: {parameter: value}} of the fitted model."""
        return {name: dict(self.model.values[name]) for name in self.model.names}


def _as_list(cases):
    return list(cases) if isinstance(cases, (list, tuple)) else [cases]


def measured_um(cases):
    """The measured deviations of one or several cases, concatenated (µm)."""
    return np.concatenate([c.positioning.error_um for c in _as_list(cases)])


def check_available(model, cases):
    """Raise :class:`InputError` when an effect of ``model`` cannot be used on a case, when
    cases fitted jointly describe different axes, or when the data are too few to fit."""
    cases = _as_list(cases)
    tracking = _tracking(model, cases)
    if tracking:
        return tracking.check_available(model, cases)
    for case in cases[1:]:
        if (case.axis.screw, case.axis.motor) != (cases[0].axis.screw, cases[0].axis.motor):
            raise InputError(f"axis.toml differs from {cases[0].folder}; cases fitted "
                             "together must describe the same axis", path=case.folder)
    for case in cases:
        if case.positioning is None:
            raise InputError("the fit needs positioning.csv", path=case.folder)
        for effect in model.effects:
            reason = effect.unavailable(case)
            if reason:
                raise InputError(f"effect {effect.name} {reason}", path=case.folder)
    shortfall = too_few_samples(model, cases)
    if shortfall:
        raise InputError(shortfall, path=cases[0].folder / "positioning.csv")


def too_few_samples(model, cases):
    """Why the cases' positioning samples cannot support a fit of ``model`` (None if they can).

    A fit needs one sample per parameter plus :data:`NOISE_DOF` for the noise, and, unless
    the samples are spread in time (a thermal test), at least two distinct targets.
    """
    cases = _as_list(cases)
    n_samples = sum(case.positioning.size for case in cases)
    n_parameters = sum(len(effect.parameters) for effect in model.effects)
    needed = n_parameters + NOISE_DOF
    if n_samples < needed:
        return (f"{n_samples} samples; a fit of {' + '.join(model.names) or 'the empty model'} "
                f"needs at least {needed} "
                f"({n_parameters} parameters + {NOISE_DOF} degrees of freedom for the noise)")
    targets = np.concatenate([case.positioning.target_mm for case in cases])
    if np.ptp(targets) < SAME_TARGET_MM and not any(case.positioning.time_s is not None
                                                     for case in cases):
        return (f"every sample is at the one target {targets[0]:g} mm (within "
                f"{SAME_TARGET_MM * 1e3:g} µm): a positioning test needs at least two targets")
    return None


def _tracking(model, cases):
    """The tracking fit module when every case is compared as a tracking case, else None."""
    from .tracking.model import is_tracking

    if all(is_tracking(case, model) for case in cases):
        from .tracking import fit as tracking_fit
        return tracking_fit
    return None


def evaluate(model, cases):
    """Statistics and residual of ``model`` as it stands (no fitting)."""
    cases = _as_list(cases)
    tracking = _tracking(model, cases)
    if tracking:
        return tracking.evaluate(model, cases)
    check_available(model, cases)
    measured = measured_um(cases)
    residual = measured - np.concatenate([model.predict_um(c) for c in cases])
    return FitResult(model, Statistics.of(measured, residual, 0), measured, residual)


def fit(model, cases, progress=None):
    """Fit every parameter of ``model`` to the cases by bounded least squares.

    Effects without values start from their :meth:`~feedaxis.effects.Effect.guess` on the
    residual of the effects before them. Variable projection finds the optimum over the
    nonlinear parameters with the linear ones solved exactly; a trust-region pass over all
    parameters then confirms it and gives the Jacobian for the uncertainties. BLAS runs on
    one thread: the matrices are small, and threads competing with other work on the machine
    made fits up to 30x slower.

    Tracking cases (tracking.csv, no positioning.csv or a model with tracking effects) go to
    :func:`feedaxis.tracking.fit.fit`.

    Parameters
    ----------
    model : Model
    cases : Case or list of Case
        Fitted jointly; their residuals are concatenated.
    progress : callable, optional
        Called once per model evaluation (for a progress bar).

    Returns
    -------
    FitResult
    """
    tracking = _tracking(model, _as_list(cases))
    if tracking:
        return tracking.fit(model, _as_list(cases), progress)
    with threadpool_limits(limits=1, user_api="blas"):
        return _fit(model, _as_list(cases), progress)


def _fit(model, cases, progress):
    check_available(model, cases)
    model = _with_starting_values(model, cases)
    measured = measured_um(cases)
    layout = _Layout(model, cases[0].axis)
    predictors = [model.predictor(case) for case in cases]

    def residual(x):
        if progress:
            progress()
        values = layout.values(x)
        return measured - np.concatenate([predict(values) for predict in predictors])

    if layout.size == 0:
        return evaluate(model, cases)
    start = _variable_projection(model, cases, layout, measured, progress)
    solution = least_squares(residual, start, bounds=layout.bounds(), x_scale="jac",
                             method="trf")
    fitted = model.with_values(layout.values(solution.x))
    sigma, undetermined, covariance = _uncertainties(solution, layout, measured.size)
    result = FitResult(fitted, Statistics.of(measured, solution.fun, layout.size), measured,
                       solution.fun, sigma, undetermined, covariance)
    _check_finite(result, cases)
    return result


def _check_finite(result, cases):
    """Raise :class:`InputError` unless the fitted values and residual are finite numbers."""
    values = [(f"{e}.{p}", v) for e, params in result.params().items() for p, v in params.items()]
    values.append(("the residual RMS", result.rms_um))
    bad = [name for name, value in values if not np.isfinite(value)]
    if bad:
        raise InputError(f"the fit gives no finite value for {', '.join(bad)}; nothing was "
                         "written (the data cannot determine the model)",
                         path=", ".join(str(case.folder) for case in cases))


def _variable_projection(model, cases, layout, measured, progress=None):
    """Starting vector at the optimum over the nonlinear parameters, the linear ones
    (``Effect.linear``) solved exactly by bounded linear least squares at every step.

    Fewer parameters for the optimiser and no poor start for the linear ones; with no
    nonlinear parameter it is one linear solve.
    """
    separators = [model.separable_predictor(case) for case in cases]
    lower, upper = layout.bounds()
    linear = layout.linear_index
    nonlinear = np.setdiff1d(np.arange(layout.size), linear)
    x = layout.start()

    def project(x_nonlinear):
        x[nonlinear] = x_nonlinear
        parts = [separate(layout.values(x)) for separate in separators]
        target_um = measured - np.concatenate([base_um for base_um, _ in parts])
        columns_um = np.vstack([columns for _, columns in parts])
        scale = np.linalg.norm(columns_um, axis=0)
        scale[scale == 0.0] = 1.0
        solution = lsq_linear(columns_um / scale, target_um, method="bvls",
                              bounds=(lower[linear] * scale, upper[linear] * scale))
        x[linear] = np.clip(solution.x / scale, lower[linear], upper[linear])
        return target_um - columns_um @ x[linear]

    def residual(x_nonlinear):
        if progress:
            progress()
        return project(x_nonlinear)

    if nonlinear.size:
        solution = least_squares(residual, x[nonlinear], bounds=(lower[nonlinear], upper[nonlinear]),
                                 x_scale="jac", method="trf")
        project(solution.x)
    else:
        project(x[nonlinear])
    margin = 1e-9 * (upper - lower)
    return np.clip(x, lower + margin, upper - margin)


def _with_starting_values(model, cases):
    """Give each effect lacking values its guess on the residual of the effects before it."""
    case = cases[0]
    running = np.array(case.positioning.error_um, dtype=float)
    values = {}
    for effect in model.effects:
        current = model.values[effect.name]
        if not current and effect.parameters:
            limits = effect.bounds(case.axis)
            current = {name: float(np.clip(value, *limits[name]))
                       for name, value in effect.guess(case, running).items()}
            values[effect.name] = current
        running = running - effect.prepare(case)(current)
    return model.with_values(values)


class _Layout:
    """Where each effect's parameters sit in the flat vector the optimiser moves."""

    def __init__(self, model, axis):
        self.model = model
        self.slots = [(e.name, p.name) for e in model.effects for p in e.parameters]
        self.linear_index = np.array([self.slots.index((e.name, name)) for e in model.effects
                                      for name in e.linear], dtype=int)
        limits = {e.name: e.bounds(axis) for e in model.effects}
        self.lower = np.array([limits[e][p][0] for e, p in self.slots], dtype=float)
        self.upper = np.array([limits[e][p][1] for e, p in self.slots], dtype=float)

    @property
    def size(self):
        return len(self.slots)

    def start(self):
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


def _uncertainties(solution, layout, n_points):
    """(standard uncertainties, undetermined parameters, covariance) from the Jacobian at
    the optimum; the covariance is in the order of ``layout.slots``.

    A parameter is undetermined when it has a share in a (nearly) singular direction of the
    Jacobian with its columns scaled to unit length (so units do not matter), or when it
    ends on a bound.
    """
    variance = float(solution.fun @ solution.fun) / max(n_points - layout.size, 1)
    scale = np.linalg.norm(solution.jac, axis=0)
    scale[scale == 0.0] = 1.0
    _, singular, vt = np.linalg.svd(solution.jac / scale, full_matrices=False)
    strong = singular > SINGULAR_RATIO * max(singular[0], 1e-300)
    covariance = ((vt[strong].T / singular[strong] ** 2) @ vt[strong] * variance
                  / np.outer(scale, scale))
    in_weak_direction = np.abs(vt[~strong]) > 0.1
    keys = [f"{effect_name}.{parameter_name}" for effect_name, parameter_name in layout.slots]
    sigma = {name: {} for name in layout.model.names}
    undetermined = {}
    for index, (effect_name, parameter_name) in enumerate(layout.slots):
        key = keys[index]
        sigma[effect_name][parameter_name] = float(np.sqrt(covariance[index, index]))
        partners = {keys[j] for row in in_weak_direction if row[index]
                    for j in np.flatnonzero(row) if j != index}
        if in_weak_direction[:, index].any():
            undetermined[key] = (f"the data cannot separate it from {', '.join(sorted(partners))}"
                                 if partners else "the data do not depend on it")
            sigma[effect_name][parameter_name] = float("nan")
        elif solution.active_mask[index] != 0:
            undetermined[key] = "ended on its bound"
    return sigma, undetermined, covariance
