"""Servo tracking deviations over time (tracking.csv with the ``[servo]`` table of axis.toml).

The tracking effects (:mod:`feedaxis.effects.tracking`) act inside the closed loop: they set
the parameters of one simulation (:func:`feedaxis.physics.servo.simulate`, the NpidServo
FMU's physics) with the controller of ``[servo]``, the plant of seed 002 Eq. 1 where the
model has no ``servo_plant``. The model predicts ``actual_mm`` from ``reference_mm`` (and
``disturbance_N``); the deviation is actual - reference in µm. The residual is serially
correlated, so the tests use the effective sample count n/τ and the uncertainties are
widened by τ. Structure is searched in time: a periodic force, a steady force, error
locked to the velocity reversals, a trend. ``compare`` gives seed 002's maximum and RMS
tracking error after the first second.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

from ..case import AXIS_FILE, CaseError
from ..fmu_map import servo_to_fmu
from ..physics.servo import ServoParams, simulate, step_counts
from ..stats.coloured import autocorrelation_time, peak_p_value
from ..stats.judge import Test
from ..stats.noise import Coloured
from .base import Measurement, Shape, Trial

SETTLING_S = 1.0  # seed 002 measures the tracking error after the first second
REVERSAL_WINDOW_S = 0.2
REVERSAL_BINS = 8
UNIFORM_SAMPLING_TOLERANCE = 0.01


def servo_params(axis, model, values=None):
    """The loop's :class:`ServoParams`: the controller of ``[servo]``, then the model's
    tracking effects with ``values`` (default the model's own)."""
    values = model.values if values is None else values
    merged = servo_to_fmu(axis.servo)
    for effect in model.effects:
        if effect.measurement == "tracking":
            merged.update({**effect.neutral, **values[effect.name]})
    return ServoParams(**merged)


class Tracking(Measurement):
    """The tracking record of a case, ready for repeated simulation."""

    kind = "tracking"
    file = "tracking.csv"
    location_key = "frequency_hz"
    location_unit = "Hz"
    coordinate_label = "time (s)"
    reference_label = "seed 002 plant"
    stages = ("effects", "structures")
    loose_share = 0.5

    def __init__(self, case):
        super().__init__(case)
        if not case.axis.servo:
            raise CaseError(Path(case.folder or ".") / AXIS_FILE, "a tracking case needs the "
                            "[servo] table (the controller as set in the drive)", column="servo")
        trace = case.tracking
        self.time_s, self.reference_mm = trace.time_s, trace.reference_mm
        self.coordinate = self.time_s
        self.disturbance_N = trace.disturbance_N
        self.measured_um = (trace.actual_mm - trace.reference_mm) * 1e3
        self.counts = step_counts(self.time_s, case.axis.servo["loop_step_s"])

    @property
    def noise(self):
        return Coloured()

    def describe(self):
        return (f"{self.size} samples over {np.ptp(self.time_s):.4g} s, "
                f"{self.case.axis.servo['controller'].upper()} controller")

    def params(self, model, values=None):
        return servo_params(self.case.axis, model, values)

    def deviation_um(self, params, disturbance_N=None):
        """Predicted deviation position - reference (µm) under ``params``, with
        ``disturbance_N`` (default the record's own) acting on the axis."""
        force = self.disturbance_N if disturbance_N is None else disturbance_N
        position_mm = simulate(params, self.time_s, self.reference_mm, force, self.counts)
        return (position_mm - self.reference_mm) * 1e3

    def core(self, model):
        return lambda values: self.deviation_um(self.params(model, values))

    def loop_response_um(self, model, disturbance_N):
        """Change of the predicted deviation (µm) when ``disturbance_N`` is added to the
        record's own force."""
        known = self.disturbance_N if self.disturbance_N is not None else 0.0
        params = self.params(model)
        return self.deviation_um(params, known + disturbance_N) - self.deviation_um(params)

    def noise_gram(self, jacobian, residual_um, variance):
        """τ · variance · J'J, τ the residual's integrated autocorrelation time: n/τ samples
        are independent."""
        return autocorrelation_time(residual_um) * variance * (jacobian.T @ jacobian)

    def shapes(self, effects):
        return (PeriodicForce(), ConstantForce(), Reversal(), TimeTrend())

    def settled(self):
        """Mask of the samples after the first second (all when none is)."""
        settled = self.time_s >= self.time_s[0] + SETTLING_S
        return settled if settled.any() else np.ones_like(settled)

    def figures(self, result):
        """Max and RMS tracking error (reference - position, mm) measured and predicted, and
        the residual (actual - predicted, µm), over the samples after the first second."""
        settled = self.settled()
        measured_mm = -result.measured_um[settled] * 1e-3
        predicted_mm = -(result.measured_um - result.residual_um)[settled] * 1e-3
        residual_um = result.residual_um[settled]
        return {"case": str(self.case.folder), "kind": self.kind,
                "effects": list(result.model.names), "samples": int(settled.sum()),
                "after_s": SETTLING_S,
                "max_tracking_error_mm": {"measured": float(np.max(np.abs(measured_mm))),
                                          "predicted": float(np.max(np.abs(predicted_mm)))},
                "rms_tracking_error_mm": {"measured": _rms(measured_mm),
                                          "predicted": _rms(predicted_mm)},
                "residual_max_um": float(np.max(np.abs(residual_um))),
                "residual_rms_um": _rms(residual_um)}

    def reversals_s(self):
        """Times (s) at which the reference velocity changes sign."""
        velocity = np.gradient(self.reference_mm, self.time_s)
        return self.time_s[1:][np.diff(np.sign(velocity)) != 0]

    def uniform_step_s(self):
        """The sampling step (s) when the record is evenly sampled, else None."""
        steps = np.diff(self.time_s)
        step = float(np.median(steps))
        return step if np.max(np.abs(steps - step)) <= UNIFORM_SAMPLING_TOLERANCE * step \
            else None


def _rms(values):
    return float(np.sqrt(np.mean(np.square(values))))


def _regress(residual, basis):
    coefficients = np.linalg.lstsq(basis, residual, rcond=None)[0]
    return coefficients, basis @ coefficients


def _sinusoid(time_s, frequency_hz):
    phase = 2.0 * np.pi * frequency_hz * (time_s - time_s[0])
    return np.column_stack((np.cos(phase), np.sin(phase), np.ones_like(phase)))


def _max_abs(fitted_um):
    return float(np.max(np.abs(fitted_um)))


class PeriodicForce(Shape):
    """The strongest sinusoid in the residual, its frequency refined between the
    neighbouring bins: the loop's response to a periodic force at that frequency (e.g. a
    cutting force at the tooth-passing frequency, seed 002 Table 2). Its p-value is
    family-wise over the searched frequencies (whitened max periodogram)."""

    kind = "periodic"
    extra = 3  # cosine, sine and the frequency

    def trials(self, measurement):
        return 1 if measurement.uniform_step_s() and measurement.size >= 8 else 0

    def trial(self, measurement, current):
        residual, time_s = current.residual_um, measurement.time_s
        step_s = measurement.uniform_step_s()
        peak_hz, p_value, ratio = peak_p_value(residual, step_s)
        bin_hz = 1.0 / (residual.size * step_s)
        refined = minimize_scalar(
            lambda f: _rss(residual - _regress(residual, _sinusoid(time_s, f))[1]),
            bounds=(max(peak_hz - bin_hz, 0.5 * bin_hz), peak_hz + bin_hz),
            method="bounded", options={"xatol": 1e-4 * bin_hz})
        best_hz = float(refined.x)
        phase = 2.0 * np.pi * best_hz * time_s
        basis = np.column_stack([measurement.loop_response_um(current.model, np.cos(phase)),
                                 measurement.loop_response_um(current.model, np.sin(phase))])
        test = Test(ratio, (1, residual.size), p_value,
                    "whitened periodogram maximum, family-wise over the frequencies searched",
                    "ratio")
        return Trial(basis, best_hz, test)

    def amplitude_um(self, measurement, fitted_um, location):
        return float(np.hypot(*_regress(fitted_um, _sinusoid(measurement.time_s, location))[0][:2]))

    def describe(self, measurement, trial, fitted_um):
        amplitude_um = self.amplitude_um(measurement, fitted_um, trial.location)
        force_N = np.hypot(*_regress(fitted_um, trial.basis)[0])
        return (f"a sinusoid at {trial.location:.4g} Hz, {amplitude_um:.3g} µm in the residual "
                f"(whitened periodogram {trial.test.statistic:.0f}x its mean level): the loop's "
                f"response to a force of {force_N:.3g} N at that frequency (e.g. a cutting "
                "force at the tooth-passing frequency)")


class ConstantForce(Shape):
    """A steady force: the fitted loop's response to 1 N, scaled."""

    kind = "constant_force"

    def trial(self, measurement, current):
        response = measurement.loop_response_um(current.model, np.ones(measurement.size))
        return Trial(response[:, None])

    def amplitude_um(self, measurement, fitted_um, location):
        return _max_abs(fitted_um)

    def describe(self, measurement, trial, fitted_um):
        force_N = _regress(fitted_um, trial.basis)[0][0]
        return f"a steady force of {force_N:+.3g} N acting on the axis"


class Reversal(Shape):
    """Error locked to the reversals of another shape than the friction effects give: a
    free profile over ``REVERSAL_WINDOW_S`` after each reversal, in ``REVERSAL_BINS`` bins."""

    kind = "reversal"
    extra = REVERSAL_BINS

    def trials(self, measurement):
        return 1 if measurement.reversals_s().size else 0

    def trial(self, measurement, current):
        time_s = measurement.time_s
        direction = np.sign(np.gradient(measurement.reference_mm, time_s))
        turns = np.flatnonzero(np.diff(direction) != 0) + 1
        basis = np.zeros((time_s.size, REVERSAL_BINS))
        width = REVERSAL_WINDOW_S / REVERSAL_BINS
        for turn in turns:
            since = time_s[turn:] - time_s[turn]
            inside = since < REVERSAL_WINDOW_S
            rows = turn + np.flatnonzero(inside)
            basis[rows, (since[inside] / width).astype(int)] += direction[turn]
        return Trial(basis)

    def amplitude_um(self, measurement, fitted_um, location):
        return _max_abs(fitted_um)

    def describe(self, measurement, trial, fitted_um):
        return (f"the residual takes a repeatable shape over {REVERSAL_WINDOW_S:g} s after "
                f"each of the {measurement.reversals_s().size} velocity reversals: a friction "
                "law other than Coulomb plus viscous (Stribeck, stick-slip), or backlash")


class TimeTrend(Shape):
    """A linear drift in time (thermal growth, a drifting encoder)."""

    kind = "trend"

    def trial(self, measurement, current):
        return Trial((measurement.time_s - measurement.time_s.mean())[:, None])

    def amplitude_um(self, measurement, fitted_um, location):
        return _max_abs(fitted_um)

    def describe(self, measurement, trial, fitted_um):
        slope = _regress(fitted_um, trial.basis)[0][0]
        return f"the residual drifts {slope:+.3g} µm/s over the record"


def _rss(values):
    return float(values @ values)
