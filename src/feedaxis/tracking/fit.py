"""Least-squares fit of a tracking model: every parameter moves the closed-loop simulation.

The residual is actual - predicted position (µm) at every sample of tracking.csv, several
cases concatenated. Its samples are far from independent, so the standard uncertainties
from the Jacobian are widened by √τ, τ the residual's integrated autocorrelation time
(the effective number of independent samples is n / τ). A parameter whose widened
uncertainty exceeds ``LOOSE_SHARE`` of its value is reported undetermined as well. Each
simulation runs :func:`feedaxis.physics.servo.simulate` (the FMU's loop, compiled); the
optimiser is scipy's trust-region reflective least squares with finite-difference
Jacobian. Statistics and uncertainties are those of positioning fits.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from ..case import AXIS_FILE, CaseError
from ..errors import InputError
from ..fit import NOISE_DOF, FitResult, Statistics, _Layout, _uncertainties
from ..physics.servo import check_runs
from .model import Record, servo_params
from .tests import autocorrelation_time

LOOSE_SHARE = 0.5


def check_available(model, cases):
    """Raise :class:`InputError` when an effect cannot be used on a case, the cases' axes
    differ, or the samples are too few for the model's parameters and the noise."""
    for case in cases[1:]:
        if case.axis != cases[0].axis:
            raise InputError(f"axis.toml differs from {cases[0].folder}; cases fitted together "
                             "must describe the same axis", path=case.folder)
    for case in cases:
        if not case.axis.servo:
            raise CaseError(Path(case.folder) / AXIS_FILE, "a tracking case needs the [servo] "
                            "table (the controller as set in the drive)", column="servo")
        for effect in model.effects:
            reason = effect.unavailable(case)
            if reason:
                raise InputError(f"effect {effect.name} {reason}", path=case.folder)
    n_samples = sum(case.tracking.time_s.size for case in cases)
    n_parameters = sum(len(effect.parameters) for effect in model.effects)
    if n_samples < n_parameters + NOISE_DOF:
        named = " + ".join(model.names) or "the empty model"
        raise InputError(f"{n_samples} samples; a fit of {named} needs at least "
                         f"{n_parameters + NOISE_DOF}",
                         path=Path(cases[0].folder) / "tracking.csv")


class Problem:
    """Measured deviations of the cases and the model's prediction for given values."""

    def __init__(self, model, cases, offset_um=0.0):
        self.model, self.cases = model, cases
        self.records = [Record.of(case) for case in cases]
        self.measured_um = np.concatenate([r.measured_um for r in self.records]) - offset_um

    def predicted_um(self, values):
        params = servo_params(self.cases[0].axis, self.model, values)
        return np.concatenate([r.predicted_um(params) for r in self.records])

    def residual_um(self, values):
        return self.measured_um - self.predicted_um(values)

    def starting_residual_um(self, values):
        """The residual at ``values`` a fit starts from or a comparison takes, refused
        (:class:`~feedaxis.physics.servo.LoopRunsAway`) when the loop runs away with them."""
        params = servo_params(self.cases[0].axis, self.model, values)
        predicted = []
        for record in self.records:
            predicted.append(record.predicted_um(params))
            check_runs(params, record.case.tracking.reference_mm + predicted[-1] * 1e-3)
        return self.measured_um - np.concatenate(predicted)


def evaluate(model, cases):
    """Statistics and residual of ``model`` as it stands (no fitting)."""
    check_available(model, cases)
    problem = Problem(model, cases)
    residual = problem.starting_residual_um(model.values)
    return FitResult(model, Statistics.of(problem.measured_um, residual, 0),
                     problem.measured_um, residual)


def fit(model, cases, progress=None, offset_um=0.0):
    """Fit every parameter of the tracking ``model`` to ``cases`` (list of Case).

    Effects without values start from their neutral values (seed 002's plant, no friction);
    a friction effect then takes one linearised least-squares step from the residual.
    ``offset_um`` (structure found by the diagnosis) is taken off the measured deviations.

    BLAS runs on one thread, as in positioning fits: the plant's 3x3 matrix exponential took
    15 ms instead of 0.05 ms with threads competing on a loaded machine.

    Returns
    -------
    FitResult
    """
    with threadpool_limits(limits=1, user_api="blas"):
        return _fit(model, cases, progress, offset_um)


def _fit(model, cases, progress, offset_um):
    check_available(model, cases)
    model = _with_starting_values(model, cases)
    problem = Problem(model, cases, offset_um)
    layout = _Layout(model, cases[0].axis)
    if layout.size == 0:
        return evaluate(model, cases)

    def residual(x):
        if progress:
            progress()
        return problem.residual_um(layout.values(x))

    problem.starting_residual_um(layout.values(layout.start()))
    solution = least_squares(residual, layout.start(), bounds=layout.bounds(), x_scale="jac",
                             method="trf")
    fitted = model.with_values(layout.values(solution.x))
    sigma, undetermined, covariance = _uncertainties(solution, layout, problem.measured_um.size)
    tau = autocorrelation_time(solution.fun)
    sigma = {name: {p: value * np.sqrt(tau) for p, value in values.items()}
             for name, values in sigma.items()}
    _flag_loose(fitted, sigma, undetermined)
    return FitResult(fitted, Statistics.of(problem.measured_um, solution.fun, layout.size),
                     problem.measured_um, solution.fun, sigma, undetermined, covariance * tau)


def _flag_loose(model, sigma, undetermined):
    """Add to ``undetermined`` the parameters the data fix only loosely."""
    for name in model.names:
        for parameter, value in model.values[name].items():
            key, spread = f"{name}.{parameter}", sigma[name][parameter]
            if key not in undetermined and spread > LOOSE_SHARE * abs(value):
                undetermined[key] = (
                    f"the data fix it only to ±{100 * spread / max(abs(value), 1e-300):.0f} %: "
                    "the reference does not excite the loop enough (a single sine fixes only "
                    "the loop's gain and phase at its frequency)")


def _with_starting_values(model, cases):
    """Neutral values for effects lacking values, then a linearised step for probed ones."""
    values = {e.name: dict(model.values[e.name]) or e.guess(cases[0], None)
              for e in model.effects}
    model = model.with_values(values)
    probed = [(e, name, step) for e in model.effects if not any(model.values[e.name].values())
              for name, step in e.probe.items()]
    if not probed:
        return model
    problem = Problem(model, cases)
    base_um = problem.measured_um - problem.starting_residual_um(model.values)
    columns = []
    for effect, name, step in probed:
        shifted = {**model.values, effect.name: {**model.values[effect.name], name: step}}
        columns.append((problem.predicted_um(shifted) - base_um) / step)
    steps = np.linalg.lstsq(np.column_stack(columns), problem.measured_um - base_um,
                            rcond=None)[0]
    for (effect, name, _), value in zip(probed, steps):
        lower, upper = effect.bounds(cases[0].axis)[name]
        values[effect.name][name] = float(np.clip(value, lower, upper))
    return model.with_values(values)
