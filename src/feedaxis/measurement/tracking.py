"""Servo tracking deviations over time (tracking.csv with the ``[servo]`` table of axis.toml).

The tracking effects (:mod:`feedaxis.effects.tracking`) act inside the closed loop: they set
the parameters of one simulation (:func:`feedaxis.physics.servo.simulate`, the NpidServo
FMU's physics) with the controller of ``[servo]``, the plant of Anang et al. 2017 Eq. 1 where the
model has no ``servo_plant``. The model predicts ``actual_mm`` from ``reference_mm`` (and
``disturbance_N``); the deviation is actual - reference in µm. The residual is serially
correlated, so the tests use the effective sample count n/τ and the uncertainties are
widened by τ. Structure is searched in time: a periodic force over the record or part of
it, a steady force, error locked to the velocity reversals; a slow drift is a nuisance of
every diagnosis, single-sample spikes are left out as outliers. ``compare`` gives the maximum and
RMS tracking error after the first second, as Anang et al. 2017 report them.

A record need not start at rest: the loop is simulated from rest on the first reference
sample over the whole record, but its samples in the first ``START_WINDOW_S`` (the start-up)
are left out of every fit, diagnosis and comparison, so a start mid-motion, whose transient
has died out by then, does not bend the plant.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy

from .. import kinds
from ..case import (AXIS_FILE, DEFAULT_LOOP_STEP_S, CaseError, _first_bad, _read_csv)
from ..fmu_map import servo_to_fmu
from ..plausibility import tracking_problems, warn_implausible
from ..physics.servo import ServoParams, check_runs, loop_budget_problem, simulate, step_counts
from ..stats.coloured import (MAX_AR_ORDER, autocorrelation_time, locate_sinusoid,
                              peak_p_value, short_time_peak, spikes)
from ..stats.judge import FAMILY_ALPHA, OUTLIER_ALPHA, Test, drift_basis
from ..stats.noise import Coloured
from .base import Measurement, Shape, Trial

SETTLING_S = 1.0  # Anang et al. 2017 measures the tracking error after the first second
# The start-up left out of every comparison. A record that starts mid-motion differs from the
# loop simulated from rest by the free response of the loop's state at the first sample; for
# the loops of Anang et al. 2017 and the tests (closed-loop poles near 250 rad/s) it falls within
# 0.1 s to 5e-6 of its peak (what is left is the integrator's slow mode), so a 100 µm
# start-up error leaves under 1 nm after 0.2 s. Profiling the state instead (fitting it as
# nuisance parameters) was tried: on a single-sine reference the fit then moved the plant to
# a lightly damped one whose free ringing imitated a persistent 62.5 Hz force.
START_WINDOW_S = 0.2
REVERSAL_WINDOW_S = 0.2
REVERSAL_BINS = 8
UNIFORM_SAMPLING_TOLERANCE = 0.01
WHOLE_RECORD_SHARE = 0.75  # of the periodic test's level: the record's periodogram, the rest
# the short-time periodogram's
ROUNDING_UM = 1e-3  # the diagnosis's resolution (diagnose.RESOLUTION_UM): below it, rounding
TRACKING_FILE = "tracking.csv"

TRACKING_COLUMNS = {"time_s": True, "reference_mm": True, "actual_mm": True,
                    "disturbance_N": False}


@dataclass(frozen=True)
class TrackingSamples:
    """tracking.csv as arrays."""

    time_s: np.ndarray
    reference_mm: np.ndarray
    actual_mm: np.ndarray
    disturbance_N: np.ndarray | None = None


def read_tracking(path, loop_step_s=DEFAULT_LOOP_STEP_S):
    """Read tracking.csv: strictly increasing time, reference and actual position.

    The control loop steps ``loop_step_s`` through every interval, so samples too far apart
    for it (:func:`feedaxis.physics.servo.loop_budget_problem`) are refused at the row.
    """
    path = Path(path)
    values, rows = _read_csv(path, TRACKING_COLUMNS)
    time_s = values["time_s"]
    _first_bad(path, np.concatenate(([False], np.diff(time_s) <= 0)), rows, "time_s",
               "time_s must be strictly increasing")
    problem = loop_budget_problem(time_s, loop_step_s)
    if problem is not None:
        raise CaseError(path, problem[1], rows[problem[0]], "time_s")
    return TrackingSamples(time_s, values["reference_mm"], values["actual_mm"],
                           values.get("disturbance_N"))


def servo_params(axis, model, values=None):
    """The loop's :class:`ServoParams`: the controller of ``[servo]``, then the model's
    tracking effects with ``values`` (default the model's own)."""
    values = model.values if values is None else values
    merged = servo_to_fmu(axis.servo)
    for effect in model.effects:
        if effect.measurement == "tracking":
            merged.update({**effect.neutral, **values[effect.name]})
    return ServoParams(**merged)


def tracking_comparison_lines(comparison):
    """Anang et al.'s (2017) figures after the first second: measured, predicted; then the residual."""
    maximum, rms = comparison["max_tracking_error_mm"], comparison["rms_tracking_error_mm"]
    return "\n".join([
        f"{comparison['samples']} samples after the first {comparison['after_s']:g} s; model: "
        f"{', '.join(comparison['effects']) or '(Anang et al. 2017 plant)'}",
        f"{'tracking error (mm)':24s} {'measured':>10s} {'predicted':>10s}",
        f"{'max':24s} {maximum['measured']:10.5f} {maximum['predicted']:10.5f}",
        f"{'RMS':24s} {rms['measured']:10.5f} {rms['predicted']:10.5f}",
        f"residual actual - predicted: max {comparison['residual_max_um']:.4g} µm, RMS "
        f"{comparison['residual_rms_um']:.4g} µm"])


@kinds.register
class Tracking(Measurement):
    """The tracking record of a case, ready for repeated simulation.

    The loop is simulated over the whole record; the samples compared (``index`` into the
    record) are those after the start-up window, less any outliers left out.
    """

    kind = "tracking"
    file = TRACKING_FILE
    capabilities = ("outliers", "nuisances", "shapes", "core", "correlated")
    measured_column = ("actual_mm", 1e-3)
    details = "feedaxis.tracking_details:tracking_details"
    views = "feedaxis.report.tracking:VIEWS"
    scenarios = "feedaxis.cosim.scenarios.tracking:SCENARIOS"
    text = staticmethod(tracking_comparison_lines)
    location_key = "frequency_hz"
    location_unit = "Hz"
    coordinate_label = "time (s)"
    reference_label = "the plant of Anang et al. 2017"
    stages = ("drift", "effects", "structures")
    loose_share = 0.5

    def __init__(self, case, index=None):
        super().__init__(case)
        if not case.axis.servo:
            raise CaseError(Path(case.folder or ".") / AXIS_FILE, "a tracking case needs the "
                            "[servo] table (the controller as set in the drive)", column="servo")
        trace = self.samples_of(case)
        self.record_time_s, self.record_reference_mm = trace.time_s, trace.reference_mm
        self.disturbance_N = trace.disturbance_N
        self.counts = step_counts(trace.time_s, case.axis.servo["loop_step_s"])
        self.index = (np.arange(_first_settled(trace.time_s), trace.time_s.size)
                      if index is None else np.asarray(index, dtype=int))
        self.time_s = self.coordinate = trace.time_s[self.index]
        self.reference_mm = trace.reference_mm[self.index]
        self.measured_um = (trace.actual_mm - trace.reference_mm)[self.index] * 1e3

    @classmethod
    def read(cls, folder, axis, duty):
        path = Path(folder) / cls.file
        if not path.exists():
            return None
        samples = read_tracking(path, axis.servo.get("loop_step_s", DEFAULT_LOOP_STEP_S))
        warn_implausible(tracking_problems(samples.reference_mm))
        return samples

    @property
    def noise(self):
        return Coloured()

    @property
    def start_s(self):
        """Time (s) from the record's first sample to the first sample compared."""
        return float(self.record_time_s[self.index[0]] - self.record_time_s[0])

    def describe(self):
        start = f" after the first {self.start_s:.3g} s" if self.start_s > 0 else ""
        return (f"{self.size} samples over {np.ptp(self.time_s):.4g} s{start}, "
                f"{self.case.axis.servo['controller'].upper()} controller")

    def rows(self, indices):
        return [int(self.index[i]) + 2 for i in indices]

    def outliers(self, residual_um):
        """Single-sample spikes in time (:func:`feedaxis.stats.coloured.spikes`, at the
        outlier level of every diagnosis); a departure of 1 nm or less is rounding (the
        diagnosis's resolution)."""
        return spikes(residual_um, OUTLIER_ALPHA, floor=ROUNDING_UM)

    def subset(self, keep):
        return Tracking(self.case, self.index[keep])

    def params(self, model, values=None):
        return servo_params(self.case.axis, model, values)

    def deviation_um(self, params, disturbance_N=None):
        """Predicted deviation position - reference (µm) at the samples under ``params``,
        with ``disturbance_N`` (over the whole record; default the record's own) acting on
        the axis; the loop is simulated from rest at the record's first sample."""
        force = self.disturbance_N if disturbance_N is None else disturbance_N
        position_mm = simulate(params, self.record_time_s, self.record_reference_mm, force,
                               self.counts)
        return (position_mm - self.record_reference_mm)[self.index] * 1e3

    def check_start(self, model, values):
        """The closed loop must not run away with ``values``
        (:class:`~feedaxis.physics.servo.LoopRunsAway`); a fit's trial values may, the
        optimiser steps back from them."""
        params = self.params(model, values)
        check_runs(params, simulate(params, self.record_time_s, self.record_reference_mm,
                                    self.disturbance_N, self.counts))

    def core(self, model):
        return lambda values: self.deviation_um(self.params(model, values))

    def loop_response_um(self, model, disturbance_N):
        """Change of the predicted deviation (µm) at the samples when ``disturbance_N``
        (over the whole record) is added to the record's own force."""
        known = self.disturbance_N if self.disturbance_N is not None else 0.0
        params = self.params(model)
        return self.deviation_um(params, known + disturbance_N) - self.deviation_um(params)

    def impulse_response_um(self, model):
        """The deviation (µm) over the record after a 1 N force held over one sample
        interval (the record's second), from that sample on: the loop's response to any
        force is its convolution with this (exactly for a linear loop: PID without Coulomb
        friction)."""
        params = self.params(model)
        known = np.zeros(self.record_time_s.size) if self.disturbance_N is None else \
            self.disturbance_N
        kicked = known.copy()
        kicked[1] += 1.0
        record_um = [(simulate(params, self.record_time_s, self.record_reference_mm, force,
                               self.counts) - self.record_reference_mm) * 1e3
                     for force in (known, kicked)]
        return (record_um[1] - record_um[0])[1:]

    def fit_window(self, model, residual_um, frequency_hz, first, last):
        """(first, last) record samples of the window over which a force at
        ``frequency_hz``, through the loop, best fits ``residual_um`` (at the samples
        compared): each edge searched to the sample within the loop's settling (the impulse
        response above 1 % of its peak) plus the whitening filter's length of its estimate,
        alternately twice. Moving an edge by a sample adds or removes one shifted impulse
        response, so each edge's search costs one convolution."""
        impulse_um = self.impulse_response_um(model)
        size = impulse_um.size + 1
        settling = int(np.flatnonzero(np.abs(impulse_um) >= 0.01 * np.max(np.abs(impulse_um)))
                       [-1]) + MAX_AR_ORDER + 1
        phase = 2.0 * np.pi * frequency_hz * self.record_time_s
        forces = np.column_stack((np.cos(phase), np.sin(phase)))
        lowest, highest = int(self.index[0]), int(self.index[-1])

        def response(a, b):
            gated = np.zeros_like(forces)
            gated[a:b + 1] = forces[a:b + 1]
            return np.column_stack([scipy.signal.fftconvolve(column, impulse_um)[:size]
                                    for column in gated.T])

        def kick(sample):
            shifted = np.zeros((size, 2))
            shifted[sample:] = np.outer(impulse_um[:size - sample], forces[sample])
            return shifted

        def misfit(columns):
            return _rss(residual_um - _regress(residual_um, columns[self.index])[1])

        def best_edge(fixed, edges, start):
            """The best of ``edges`` (moving away from the first, each adding a sample)."""
            columns = response(edges[0], fixed) if start else response(fixed, edges[0])
            best = (misfit(columns), edges[0])
            for edge in edges[1:]:
                columns = columns + kick(edge)
                best = min(best, (misfit(columns), edge))
            return best[1]

        for _ in range(2):
            first = best_edge(last, list(range(min(first + settling, last),
                                               max(first - settling, lowest) - 1, -1)), True)
            last = best_edge(first, list(range(max(last - settling, first),
                                               min(last + settling, highest) + 1)), False)
        return first, last

    def noise_gram(self, jacobian, residual_um, variance):
        """τ · variance · J'J, τ the residual's integrated autocorrelation time: n/τ samples
        are independent."""
        return autocorrelation_time(residual_um) * variance * (jacobian.T @ jacobian)

    def confounded(self, model, slots, jacobian, residual_um, sigma):
        """The parameters a measurement delay would move unseen: actual_mm recorded late by
        δ reads x(t - δ) ≈ x(t) - ẋ·δ, so the residual moves by -ẋ·δ (ẋ the predicted
        velocity). Its least-squares projection on the Jacobian's columns is what the
        parameters absorb (β per second of delay); the rest ``u`` is what the residual would
        show, so a delay estimated on top of the fit has the standard error σ·√τ / ‖u‖.
        Reported: when a delay of one sample interval lies within 3 standard errors (the
        record cannot see it), each parameter it moves by more than its standard
        uncertainty."""
        step_s = float(np.median(np.diff(self.time_s)))
        position_mm = self.reference_mm + (self.measured_um - residual_um) * 1e-3
        velocity_um_s = np.gradient(position_mm, self.time_s) * 1e3
        absorbed, *_ = np.linalg.lstsq(jacobian, velocity_um_s, rcond=None)
        left_um_s = float(np.linalg.norm(velocity_um_s - jacobian @ absorbed))
        dof = max(residual_um.size - len(slots), 1)
        noise_um = float(np.sqrt(residual_um @ residual_um / dof
                                 * autocorrelation_time(residual_um)))
        unseen_s = 3.0 * noise_um / max(left_um_s, 1e-300)
        if unseen_s <= step_s:
            return {}
        units = {(e.name, p.name): p.unit for e in model.effects for p in e.parameters}
        moved = {slot: shift * step_s for slot, shift in zip(slots, absorbed)
                 if abs(shift * step_s) > sigma[slot[0]][slot[1]]}
        keys = [f"{effect}.{parameter}" for effect, parameter in moved]
        return {key: (
            f"the reference cannot separate it from a measurement delay (actual_mm recorded "
            f"late, outside the loop): the residual would not show a delay under "
            f"{1e3 * unseen_s:.3g} ms (3 standard errors), and each {1e3 * step_s:.3g} ms of it "
            f"moves this parameter by {shift:+.3g} {units[slot]} "
            f"({abs(shift) / sigma[slot[0]][slot[1]]:.0f} standard uncertainties)"
            + (f", {', '.join(k for k in keys if k != key)} with it" if len(keys) > 1 else ""))
            for key, (slot, shift) in zip(keys, moved.items())}

    def nuisances(self):
        """A slow drift in time (:class:`TimeDrift`), fitted with every model so it never
        passes for an effect or a force."""
        drift = TimeDrift()
        return [("drift", drift, drift.trial(self, None).basis)]

    def shapes(self, effects):
        return (PeriodicForce(), ConstantForce(), Reversal())

    def settled(self):
        """Mask of the samples after the record's first second (all when none is)."""
        settled = self.time_s >= self.record_time_s[0] + SETTLING_S
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
        """The sampling step (s) when the record is evenly sampled over the samples compared
        (outliers left out are gaps of it), else None."""
        steps = np.diff(self.record_time_s[self.index[0]:self.index[-1] + 1])
        if steps.size == 0:
            return None
        step = float(np.median(steps))
        return step if np.max(np.abs(steps - step)) <= UNIFORM_SAMPLING_TOLERANCE * step \
            else None

    def gridded(self, values):
        """(time_s, values) on the record's samples from the first to the last compared,
        ``values`` (one per sample compared) interpolated linearly over the outliers left
        out: what the spectral tests take."""
        grid = np.arange(self.index[0], self.index[-1] + 1)
        return self.record_time_s[grid], np.interp(grid, self.index, values)


def _first_settled(time_s):
    """Index of the first sample after the start-up window; 0 (the record is taken to start
    at rest) when fewer than half the samples lie after it."""
    first = int(np.searchsorted(time_s, time_s[0] + START_WINDOW_S))
    return first if 2 * first <= time_s.size else 0


def _rms(values):
    return float(np.sqrt(np.mean(np.square(values))))


def _regress(residual, basis):
    coefficients = np.linalg.lstsq(basis, residual, rcond=None)[0]
    return coefficients, basis @ coefficients


def _sinusoid(time_s, frequency_hz):
    phase = 2.0 * np.pi * frequency_hz * (time_s - time_s[0])
    return np.column_stack((np.cos(phase), np.sin(phase), np.ones_like(phase)))


def _rss(values):
    return float(values @ values)


def _max_abs(fitted_um):
    return float(np.max(np.abs(fitted_um)))


class PeriodicForce(Shape):
    """The strongest sinusoid in the residual, over the whole record or during part of it:
    the loop's response to a periodic force at that frequency (e.g. a cutting force at the
    tooth-passing frequency, Anang et al. 2017 Table 2), switched on and off where the residual shows
    it (a cut that lasts part of the record).

    Two searches of the whitened residual (:mod:`feedaxis.stats.coloured`): the record's
    periodogram maximum (a force lasting the record) and the short-time periodogram's
    (a burst), their p-values weighted by ``WHOLE_RECORD_SHARE`` and the rest of the
    level (a weighted Bonferroni: the record's search, the stronger for a lasting force,
    keeps most of it). The window and frequency are then found by least squares
    (:func:`locate_sinusoid`), the window kept when it describes the sinusoid better than
    the whole record does.
    """

    kind = "periodic"
    extra = 3  # cosine, sine and the frequency

    def trials(self, measurement):
        return 1 if measurement.uniform_step_s() and measurement.size >= 8 else 0

    def trial(self, measurement, current):
        time_s, residual = measurement.gridded(current.residual_um)
        step_s = measurement.uniform_step_s()
        whole_hz, whole_p, whole_ratio = peak_p_value(residual, step_s, robust=True)
        burst = short_time_peak(residual, step_s)
        share = 1.0 if burst is None else WHOLE_RECORD_SHARE
        burst_p = 1.0 if burst is None else min(1.0, burst.p_value / (1.0 - share))
        whole_p = min(1.0, whole_p / share)
        if burst_p < whole_p:
            frequency_hz, bin_hz = burst.frequency_hz, 1.0 / (burst.window * step_s)
            test = Test(burst.ratio, (1, burst.trials), burst_p,
                        f"short-time periodogram maximum of the whitened residual, family-wise "
                        f"over {burst.trials} windows and frequencies and the whole record",
                        "ratio")
        else:
            frequency_hz, bin_hz = whole_hz, 1.0 / (residual.size * step_s)
            test = Test(whole_ratio, (1, residual.size), whole_p,
                        "whitened periodogram maximum, family-wise over the frequencies "
                        "searched and the short-time windows", "ratio")
        first, stop, frequency_hz, localised = locate_sinusoid(residual, time_s, frequency_hz,
                                                               bin_hz)
        record_s = measurement.record_time_s
        on, start_s, end_s = 1.0, float(time_s[0]), float(time_s[-1])
        if localised:
            first, last = first + int(measurement.index[0]), stop - 1 + int(measurement.index[0])
            if test.p_value < FAMILY_ALPHA:  # only a sinusoid that may pass is refined
                first, last = measurement.fit_window(current.model, current.residual_um,
                                                     frequency_hz, first, last)
            start_s, end_s = float(record_s[first]), float(record_s[last])
            on = np.zeros(record_s.size)
            on[first:last + 1] = 1.0
        phase = 2.0 * np.pi * frequency_hz * record_s
        basis = np.column_stack([measurement.loop_response_um(current.model, np.cos(phase) * on),
                                 measurement.loop_response_um(current.model, np.sin(phase) * on)])
        return Trial(basis, frequency_hz, test,
                     {"start_s": start_s, "end_s": end_s, "localised": localised})

    def amplitude_um(self, measurement, fitted_um, location):
        """The sinusoid's amplitude where the loop's response to the force is on (at least
        half its largest value)."""
        on = np.abs(fitted_um) >= 0.5 * _max_abs(fitted_um)
        if on.sum() < 3:
            return _max_abs(fitted_um)
        return float(np.hypot(*_regress(fitted_um[on], _sinusoid(measurement.time_s[on],
                                                                 location))[0][:2]))

    def describe(self, measurement, trial, fitted_um):
        amplitude_um = self.amplitude_um(measurement, fitted_um, trial.location)
        force_N = np.hypot(*_regress(fitted_um, trial.basis)[0])
        if trial.extra["localised"]:
            return (f"a sinusoid at {trial.location:.4g} Hz from {trial.extra['start_s']:.4g} s "
                    f"to {trial.extra['end_s']:.4g} s, {amplitude_um:.3g} µm in the residual "
                    f"(short-time periodogram {trial.test.statistic:.0f}x the noise level): the "
                    f"loop's response to a force of {force_N:.3g} N at that frequency during "
                    "that time (e.g. a cutting force while the tool is engaged)")
        return (f"a sinusoid at {trial.location:.4g} Hz, {amplitude_um:.3g} µm in the residual "
                f"(whitened periodogram {trial.test.statistic:.0f}x its mean level): the loop's "
                f"response to a force of {force_N:.3g} N at that frequency (e.g. a cutting "
                "force at the tooth-passing frequency)")


class ConstantForce(Shape):
    """A steady force: the fitted loop's response to 1 N, scaled."""

    kind = "constant_force"

    def trial(self, measurement, current):
        response = measurement.loop_response_um(current.model,
                                               np.ones(measurement.record_time_s.size))
        return Trial(response[:, None])

    def amplitude_um(self, measurement, fitted_um, location):
        return _max_abs(fitted_um)

    def describe(self, measurement, trial, fitted_um):
        force_N = _regress(fitted_um, trial.basis)[0][0]
        return (f"a steady force of {force_N:+.3g} N acting on the axis (in a record that "
                "starts mid-motion, equally the controller's integral term at the first sample: "
                "the record cannot tell them apart)")


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
        # each window's last sample or one past it: ``since < window`` below decides
        ends = np.searchsorted(time_s, time_s[turns] + REVERSAL_WINDOW_S, side="right") + 1
        for turn, end in zip(turns, ends):
            since = time_s[turn:end] - time_s[turn]
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


class TimeDrift(Shape):
    """A slow drift in time, linear and quadratic (thermal growth of the screw under a
    rotary encoder, a drifting scale): a nuisance of every diagnosis, not an effect."""

    kind = "drift"
    extra = 2

    def trial(self, measurement, current):
        return Trial(drift_basis(measurement.time_s))

    def amplitude_um(self, measurement, fitted_um, location):
        return _max_abs(fitted_um)

    def describe(self, measurement, trial, fitted_um):
        change = float(fitted_um[-1] - fitted_um[0])
        span_s = float(np.ptp(measurement.time_s))
        return (f"the deviation drifts {change:+.3g} µm over the record ({span_s:.3g} s), the "
                "same whatever the motion: a drift of the measurement (thermal growth, a "
                "drifting scale), not an effect of the loop")
