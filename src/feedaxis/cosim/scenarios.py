"""Scenarios on the co-simulated axis that write measurement cases (docs/case-format.md).

- :func:`simulate_iso230`: ISO 230-2 positioning cycle -> ``axis.toml`` + ``positioning.csv``;
- :func:`simulate_thermal`: a duty cycle with measurement passes -> + ``duty.csv``;
- :func:`simulate_tracking`: sinusoidal tracking (Anang et al. 2017) -> ``axis.toml`` + ``tracking.csv``.

Each writes what its in-memory twin (:func:`run_iso230`, :func:`run_thermal`,
:func:`run_tracking`, by name in :data:`RUNS`) returns: a :class:`ScenarioRun` holding the
case's columns, the scenario's figures and the curve a sweep bands (:mod:`.sweep`).

Every motion is a sequence of :class:`~feedaxis.physics.thermal.DutySegment` (travel between
two points at a feed, or standing still), the same segments duty.csv holds, so what the
thermal scenario writes is exactly the motion it simulated. The servo's reference input
k is the motion at t_{k+1}: NpidServo ramps its reference linearly over each communication
step, so it then follows the motion without the one-step delay of a held sample.

A measured deviation is what a laser interferometer sees: table position - target, with
the table position = servo position + the three FMUs' errors (``table_position_mm``).
Ctrl-C stops the run cleanly; the samples computed so far are written as a (shorter) case
and :class:`ScenarioInterrupted` says where.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..case import PHYSICAL_RANGE, CaseError, range_problem, read_case, write_case
from ..kinds import kinds
from ..measurement.positioning import PositioningSamples
from ..compensate import thermal_error_um
from ..errors import InputError, ParameterError
from ..iso230 import iso230_figures, per_target
from ..fmu_map import AXIS_KEYS, SERVO_KEYS, servo_from_fmu
from ..physics.checks import require_positive
from ..physics.servo import MAX_INTERVAL_STEPS, MAX_LOOP_STEPS, ServoParams
from ..physics.thermal import DutySegment
from .master import SimulationInterrupted
from .physics_check import start_value

ISO_REFERENCE_C = 20.0
SETTLE_S = 1.0
MAX_TRAVEL_MM = PHYSICAL_RANGE["reference_mm"][1]  # beyond any physical axis
MAX_SAMPLES = 100_000  # samples of one simulated test (ISO 230-2: 5 runs x 2 x ~20 targets)
MAX_MACRO_STEPS = 1e9  # 11.6 days of axis time at 1 ms: days of computing
TEETH = 2
# F0 (N) calibrated on one row of Anang et al. 2017 Table 2 (PID, 0.4 Hz, 10 mm, 1500 rpm: 0.0757 mm)
# with the assumed force_constant_N_per_V = 100; it then gives 0.2211 mm at 0.7 Hz, 20 mm,
# 1500 rpm (paper 0.2217), but falls faster with spindle speed than the paper.
CUTTING_FORCE_N = 1.4
# Positioning tests (iso230, thermal) run the servo with a type-1 plant (a0 = 0): with the
# a0 = 193.3 1/s² of Anang et al. 2017 and its tiny integral gain the loop keeps a static error of about
# target/364 (1.4 mm at 500 mm), which no CNC axis shows and which would swamp the errors
# a positioning test is about. Tracking keeps the published plant; --set overrides both.
POSITIONING_SERVO = {"NpidServo": {"plant_stiffness_per_s2": 0.0}}


TRACKING_SERIES_POINTS = 200  # tracking-error samples a sweep keeps per trial for its bands


@dataclass(frozen=True)
class Series:
    """The curve of one run that a sweep gives bands of: ``y`` against ``x``, one line per
    value of ``group`` (approach direction, target, ...)."""

    x_name: str
    x: np.ndarray
    y_name: str
    y: np.ndarray
    group: tuple


@dataclass(frozen=True)
class ScenarioRun:
    """One scenario run in memory.

    ``tables`` are the case's columns by file (``positioning``, ``duty``, ``tracking``),
    ``figures`` the scenario's figures (µm or mm, named with their unit), ``summary`` what
    ``feedaxis simulate`` reports, ``parameters`` the overrides it ran with; ``completed``
    is False after Ctrl-C (the tables then hold what was reached).
    """

    name: str
    parameters: dict
    tables: dict
    figures: dict
    series: Series
    summary: dict
    completed: bool


class ScenarioInterrupted(KeyboardInterrupt):
    """Ctrl-C: the partial result was written; ``message`` says where and how much."""

    def __init__(self, message):
        super().__init__(message)
        self.message = message


@dataclass(frozen=True)
class Sample:
    """A positioning sample: at ``time_s`` the axis stands at ``target_mm``."""

    time_s: float
    target_mm: float
    direction: int
    run: int


class Motion:
    """Consecutive motion segments from t = 0 and the positioning samples taken on them."""

    def __init__(self, start_mm):
        self.segments, self.ambient_C, self.samples = [], [], []
        self.position_mm, self.time_s = float(start_mm), 0.0

    def move(self, to_mm, feed_mm_min, ambient_C=None):
        """Travel to ``to_mm`` at ``feed_mm_min`` (nothing when already there)."""
        distance_mm = abs(to_mm - self.position_mm)
        if distance_mm > 1e-12:
            self._add(distance_mm / (feed_mm_min / 60.0), feed_mm_min, self.position_mm, to_mm,
                      ambient_C)
            self.position_mm = float(to_mm)

    def dwell(self, duration_s, ambient_C=None):
        """Stand still at the current position."""
        self._add(duration_s, 0.0, self.position_mm, self.position_mm, ambient_C)

    def cycle(self, duration_s, feed_mm_min, from_mm, to_mm, ambient_C=None):
        """Back and forth between two points, starting at ``from_mm`` (a duty.csv row)."""
        self._add(duration_s, feed_mm_min, from_mm, to_mm, ambient_C)
        self.position_mm = float(DutySegment(0.0, duration_s, feed_mm_min, from_mm,
                                             to_mm).nut_position_mm(duration_s))

    def measure(self, target_mm, feed_mm_min, dwell_s, run, ambient_C=None):
        """Approach ``target_mm``, dwell and sample at the end of the dwell."""
        direction = 1 if target_mm >= self.position_mm else -1
        self.move(target_mm, feed_mm_min, ambient_C)
        self.dwell(dwell_s, ambient_C)
        self.samples.append(Sample(self.time_s, float(target_mm), direction, run))

    def _add(self, duration_s, feed_mm_min, from_mm, to_mm, ambient_C):
        self.segments.append(DutySegment(self.time_s, duration_s, feed_mm_min, from_mm, to_mm))
        self.ambient_C.append(ambient_C)
        self.time_s += duration_s

    def position_at(self, time_s):
        """Commanded position (mm) at the times ``time_s`` (array)."""
        return self._per_segment(time_s, lambda segment, t, _: segment.nut_position_mm(t))

    def ambient_at(self, time_s):
        """Ambient temperature (°C) of the segment at each time, ISO 20 °C when unknown."""
        return self._per_segment(
            time_s, lambda _, t, ambient: np.full(t.shape, ISO_REFERENCE_C if ambient is None
                                                  else ambient))

    def _per_segment(self, time_s, value):
        starts = np.array([s.start_s for s in self.segments])
        index = np.clip(np.searchsorted(starts, time_s, side="right") - 1, 0,
                        len(self.segments) - 1)
        result = np.empty(np.shape(time_s))
        for i in np.unique(index):
            inside = index == i
            result[inside] = value(self.segments[i], time_s[inside], self.ambient_C[i])
        return result

    def duty_columns(self, until_s=None):
        """duty.csv columns of the motion, cut at ``until_s`` (an interrupted run)."""
        end_s = self.time_s if until_s is None else until_s
        kept = [(s, a) for s, a in zip(self.segments, self.ambient_C) if s.start_s < end_s]
        rows = [replace(s, duration_s=min(s.duration_s, end_s - s.start_s)) for s, _ in kept]
        columns = {name: [getattr(s, name) for s in rows]
                   for name in ("start_s", "duration_s", "feed_mm_min", "from_mm", "to_mm")}
        if any(a is not None for _, a in kept):
            columns["ambient_C"] = [ISO_REFERENCE_C if a is None else a for _, a in kept]
        return columns


def iso230_targets(n_targets, spacing_mm, first_mm=0.0):
    """Targets P_i = (i - 1) p + r_i (ISO 230-2) with a different offset r_i at each.

    r_i = p (frac(0.618034 i) - 0.5) / 5 stays within ±10 % of the spacing p and differs at
    every target, so periodic errors (screw lead, motor steps) are not sampled in phase.
    """
    if n_targets > MAX_SAMPLES:
        raise ParameterError(f"must be 2 to {MAX_SAMPLES}, got {n_targets}", "--targets")
    if n_targets < 2 or not spacing_mm > 0:
        raise ParameterError(f"iso230 needs at least 2 targets (got {n_targets}) and a "
                             f"spacing > 0 (got {spacing_mm})", "--targets/--spacing-mm")
    i = np.arange(1, n_targets + 1)
    offsets_mm = spacing_mm * (np.mod(0.618034 * i, 1.0) - 0.5) / 5.0
    return first_mm + (i - 1) * spacing_mm + offsets_mm


def iso230_motion(targets_mm, runs=5, feed_mm_min=3000.0, dwell_s=0.5, overrun_mm=2.0):
    """The ISO 230-2 linear cycle: each run approaches every target in +, then in -.

    Each run starts ``overrun_mm`` below the first target, stops at every target in
    ascending order (approach +), overruns the last one, then stops at every target in
    descending order (approach -) and overruns the first one.
    """
    targets_mm = np.sort(np.asarray(targets_mm, dtype=float))
    _require_positive(runs=runs, feed_mm_min=feed_mm_min, dwell_s=dwell_s)
    if 2 * len(targets_mm) * runs > MAX_SAMPLES:
        raise ParameterError(f"{len(targets_mm)} targets x {runs} runs x 2 directions is more "
                             f"than the {MAX_SAMPLES} samples a test may hold", "runs")
    if overrun_mm < 0:
        raise ParameterError(f"must be >= 0, got {overrun_mm}", "overrun_mm")
    motion = Motion(targets_mm[0] - overrun_mm)
    for run in range(1, runs + 1):
        for target in targets_mm:
            motion.measure(target, feed_mm_min, dwell_s, run)
        motion.move(targets_mm[-1] + overrun_mm, feed_mm_min)
        for target in targets_mm[::-1]:
            motion.measure(target, feed_mm_min, dwell_s, run)
        motion.move(targets_mm[0] - overrun_mm, feed_mm_min)
    return motion


def thermal_motion(duty, targets_mm, every_s, feed_mm_min=3000.0, dwell_s=0.5):
    """The duty of ``duty`` with a measurement pass over ``targets_mm`` every ``every_s``.

    A pass (approach each target in the given order at ``feed_mm_min``, dwell, sample) runs
    at t = 0 (cold axis), after every ``every_s`` of duty time and at the end of the duty.
    Duty segments keep their durations: a segment cut by a pass resumes from its
    ``from_mm`` after it, reached by a move at ``feed_mm_min``; the motion (and the duty.csv
    written) is the input duty with these passes and moves inserted.
    """
    _require_positive(every_s=every_s, feed_mm_min=feed_mm_min, dwell_s=dwell_s)
    if (duty.end_s / every_s + 2) * len(targets_mm) > MAX_SAMPLES:
        raise ParameterError(f"a pass over {len(targets_mm)} targets every {every_s:g} s of a "
                             f"{duty.end_s:g} s duty is more than the {MAX_SAMPLES} samples a "
                             "test may hold", "every_s")
    cuts_s = list(np.arange(every_s, duty.end_s, every_s))
    ambient = list(duty.ambient_C) if duty.ambient_C is not None else [None] * len(duty.segments)
    motion = Motion(targets_mm[0])
    passes = 0

    def measurement_pass(ambient_C):
        nonlocal passes
        passes += 1
        for target in targets_mm:
            motion.measure(target, feed_mm_min, dwell_s, passes, ambient_C)

    measurement_pass(ambient[0])
    for segment, ambient_C in zip(duty.segments, ambient):
        edges_s = [segment.start_s] + [c for c in cuts_s if segment.start_s < c < segment.end_s]
        for piece_start_s, piece_end_s in zip(edges_s, edges_s[1:] + [segment.end_s]):
            motion.move(segment.from_mm, feed_mm_min, ambient_C)
            motion.cycle(piece_end_s - piece_start_s, segment.feed_mm_min, segment.from_mm,
                         segment.to_mm, ambient_C)
            if any(abs(piece_end_s - c) < 1e-9 for c in cuts_s + [duty.end_s]):
                measurement_pass(ambient_C)
    return motion


def run_motion(master, motion, parameters=None, progress=None):
    """Drive the axis along ``motion``; return (rows at the samples, completed flag).

    The run records at every sample time; on Ctrl-C it returns the samples reached.
    """
    h = master.system.macro_step_s
    stop_s = _stop_time_s(motion.time_s, h)
    inputs = {"position_ref_mm": lambda t: motion.position_at(t + h),
              "ambient_C": motion.ambient_at}
    times_s = [s.time_s for s in motion.samples]
    try:
        rows = master.run(stop_s, inputs, parameters, record_at_s=times_s, progress=progress)
        completed = True
    except SimulationInterrupted as stopped:
        rows, completed = stopped.partial, False
    if rows.size < 2:
        raise ScenarioInterrupted("interrupted before the first sample; nothing written")
    return rows[1:], completed


def run_iso230(master, targets_mm, runs=5, feed_mm_min=3000.0, dwell_s=0.5, overrun_mm=2.0,
               parameters=None, progress=None):
    """Simulate an ISO 230-2 positioning test in memory: the samples (with ``time_s``) and
    the motion simulated (moves and dwells, which warm the screw) as the duty.

    Parameters
    ----------
    master : Master
    targets_mm : array_like
        Target positions P_i (mm), e.g. from :func:`iso230_targets`.
    runs : int
        Runs in each direction (ISO 230-2: 5).
    feed_mm_min, dwell_s, overrun_mm : float
        Travel feed between targets (mm/min), dwell at each target before the sample (s),
        overrun beyond the end targets (mm).
    parameters : dict, optional
        {component: {parameter: value}} for this run (e.g. a fitted model's FMU values),
        over :data:`POSITIONING_SERVO`.

    Returns
    -------
    ScenarioRun
        Figures: the ISO 230-2 figures (:func:`feedaxis.iso230.iso230_figures`) and the
        deviation range; series: the mean deviation at each target per approach direction.
        After Ctrl-C only the complete runs (ISO 230-2 statistics need equal runs).
    """
    parameters = _positioning_parameters(parameters)
    motion = iso230_motion(targets_mm, runs, feed_mm_min, dwell_s, overrun_mm)
    rows, completed = run_motion(master, motion, parameters, progress=progress)
    name = "simulated ISO 230-2 test"
    if not completed:
        complete_runs = rows.size // (2 * len(targets_mm))
        if complete_runs == 0:
            raise ScenarioInterrupted("interrupted before the first complete run; nothing "
                                      "written")
        rows = rows[:complete_runs * 2 * len(targets_mm)]
        name += f" (interrupted: {complete_runs} of {runs} runs)"
    positioning = _positioning_columns(motion.samples[:rows.size], rows, with_time=True)
    until_s = None if completed else float(positioning["time_s"][-1])
    target_mm, error_um = positioning["target_mm"], positioning["error_um"]
    direction = np.asarray(positioning["direction"], dtype=float)
    figures = {**_numbers(iso230_figures(target_mm, error_um, direction)),
               **_deviation_range(error_um)}
    return ScenarioRun(name, parameters, {"positioning": positioning,
                                          "duty": motion.duty_columns(until_s)}, figures,
                       _mean_deviation_series(target_mm, error_um, direction),
                       _positioning_summary(positioning, motion.samples), completed)


def simulate_iso230(out, master, targets_mm, runs=5, feed_mm_min=3000.0, dwell_s=0.5,
                    overrun_mm=2.0, parameters=None, progress=None, noise=None):
    """Simulate an ISO 230-2 positioning test (:func:`run_iso230`) and write it as a case
    folder ``out`` (it must not exist); return the case folder, number of samples and the
    deviation range (µm)."""
    run = run_iso230(master, targets_mm, runs, feed_mm_min, dwell_s, overrun_mm, parameters,
                     progress)
    return write_run(out, master, run, noise)


def run_thermal(master, duty, targets_mm, every_s, feed_mm_min=3000.0, dwell_s=0.5,
                parameters=None, progress=None):
    """Simulate a thermal test in memory: the duty with measurement passes.

    Parameters
    ----------
    master : Master
    duty : feedaxis.case.Duty
        The heating duty (e.g. ``read_duty("duty.csv")``).
    targets_mm : sequence of float
        Targets of every measurement pass, visited in this order.
    every_s : float
        Duty time between measurement passes (s).
    feed_mm_min, dwell_s : float
        Feed of the measurement moves and dwell before each sample.
    parameters : dict, optional

    Returns
    -------
    ScenarioRun
        Figures: the thermal error (each target's drift from its first visit, as
        ``feedaxis compensate`` measures it) at its largest and as RMS, and the deviation
        range; series: the thermal error against time, per target and direction.
    """
    if len(targets_mm) < 1:
        raise ParameterError("thermal needs at least one target", "targets")
    parameters = _positioning_parameters(parameters)
    motion = thermal_motion(duty, targets_mm, every_s, feed_mm_min, dwell_s)
    rows, completed = run_motion(master, motion, parameters, progress=progress)
    positioning = _positioning_columns(motion.samples[:rows.size], rows, with_time=True)
    until_s = None if completed else float(positioning["time_s"][-1])
    name = "simulated thermal test" + ("" if completed else
                                       f" (interrupted at t = {until_s:g} s)")
    samples = PositioningSamples(positioning["target_mm"], positioning["error_um"],
                                 np.asarray(positioning["direction"], dtype=float),
                                 time_s=np.asarray(positioning["time_s"]), has_direction=True)
    drift_um = thermal_error_um(samples)
    figures = {"max_thermal_error_um": float(np.max(np.abs(drift_um))),
               "rms_thermal_error_um": float(np.sqrt(np.mean(drift_um ** 2))),
               **_deviation_range(positioning["error_um"])}
    series = Series("time_s", samples.time_s, "thermal_error_um", drift_um,
                    tuple(f"{t:g} mm {'+' if d > 0 else '-'}"
                          for t, d in zip(samples.target_mm, samples.direction)))
    return ScenarioRun(name, parameters, {"positioning": positioning,
                                          "duty": motion.duty_columns(until_s)},
                       figures, series, _positioning_summary(positioning, motion.samples),
                       completed)


def simulate_thermal(out, master, duty, targets_mm, every_s, feed_mm_min=3000.0,
                     dwell_s=0.5, parameters=None, progress=None, noise=None):
    """Simulate a thermal test (:func:`run_thermal`) and write duty.csv + positioning.csv
    into the case folder ``out``; return its summary."""
    run = run_thermal(master, duty, targets_mm, every_s, feed_mm_min, dwell_s, parameters,
                      progress)
    return write_run(out, master, run, noise)


def cutting_force_N(time_s, spindle_rpm, force_N, teeth=TEETH):
    """Milling force at the tooth-passing frequency, an assumption (Anang et al. 2017 gives none).

    F(t) = F0 · (1500 / n) · (1 + sin(2π z n / 60 · t)) / 2: the mean force falls with
    spindle speed n as the feed per tooth does (Anang et al. 2017 explain Table 2 so), z teeth.
    """
    _require_positive(spindle_rpm=spindle_rpm)
    scale = force_N * 1500.0 / spindle_rpm
    return scale * 0.5 * (1.0 + np.sin(2 * np.pi * teeth * spindle_rpm / 60.0 * time_s))


def run_tracking(master, frequency_hz, amplitude_mm, duration_s, controller="pid",
                 spindle_rpm=None, force_N=CUTTING_FORCE_N, parameters=None, progress=None,
                 record_control=False):
    """Sinusoidal tracking (Anang et al. 2017) in memory.

    Parameters
    ----------
    master : Master
    frequency_hz, amplitude_mm, duration_s : float
        Reference A sin(2π f t) (mm) for ``duration_s`` seconds.
    controller : {"pid", "npid", "cascade"}
        PID (Anang et al. 2017 Eq. 6), NPID (Eq. 8) or a drive's cascade (NpidServo's
        ``kp_per_s``, ``kv_V_s_per_mm``, ``tn_s``, ``velocity_feedforward``).
    spindle_rpm : float, optional
        Adds the cutting force of :func:`cutting_force_N` (1500/2500/3500 rpm in Anang et al. 2017).
    force_N : float
        Cutting-force amplitude F0 at 1500 rpm (N); see :data:`CUTTING_FORCE_N`.
    record_control : bool
        Write the controller output as tracking.csv's ``control_V``, as a drive records it.

    Returns
    -------
    ScenarioRun
        Figures: ``max_tracking_error_mm`` and ``rms_tracking_error_mm`` over t > 1 s (after
        the start-up transient, as the Anang et al. 2017 Table 1 reproduction); series: the tracking
        error against time at :data:`TRACKING_SERIES_POINTS` evenly spaced steps.
    """
    _require_positive(frequency_hz=frequency_hz, amplitude_mm=amplitude_mm,
                      duration_s=duration_s)
    h = master.system.macro_step_s
    if amplitude_mm > MAX_TRAVEL_MM:
        raise ParameterError(f"must be <= {MAX_TRAVEL_MM:g} mm (beyond any physical axis), "
                             f"got {amplitude_mm:g}", "amplitude_mm")
    if frequency_hz >= 0.5 / h:
        raise ParameterError(f"must be below {0.5 / h:g} Hz, the Nyquist frequency of the "
                             f"{h:g} s macro step, got {frequency_hz:g}", "frequency_hz")
    if not duration_s > SETTLE_S:
        raise ParameterError(f"must exceed {SETTLE_S:g} s: the tracking error is measured "
                             f"after the first {SETTLE_S:g} s (the start-up transient), got "
                             f"{duration_s:g}", "duration_s")
    if controller not in ("pid", "npid", "cascade"):
        raise ParameterError(f"must be pid, npid or cascade, got {controller!r}", "controller")
    overrides = {**(parameters or {})}
    overrides["NpidServo"] = {**overrides.get("NpidServo", {}), "nonlinear": False,
                              "controller": controller}
    stop_s = _stop_time_s(duration_s, h)
    servo = master.system.with_parameters(overrides).component("NpidServo").parameters
    _check_loop_budget(h, stop_s, servo.get("time_step_s", ServoParams.time_step_s))

    def reference_mm(t):
        return amplitude_mm * np.sin(2 * np.pi * frequency_hz * t)

    inputs = {"position_ref_mm": lambda t: reference_mm(t + h)}
    if spindle_rpm is not None:
        inputs["disturbance_N"] = lambda t: cutting_force_N(t, spindle_rpm, force_N)
    try:
        rows, completed = master.run(stop_s, inputs, overrides, progress=progress), True
    except SimulationInterrupted as stopped:
        rows, completed = stopped.partial, False
    rows = rows[1:]
    if rows.size == 0:
        raise ScenarioInterrupted("interrupted before the first step; nothing written")
    tracking = {"time_s": rows["time"], "reference_mm": reference_mm(rows["time"]),
                "actual_mm": rows["NpidServo.position_mm"]}
    if spindle_rpm is not None:
        tracking["disturbance_N"] = cutting_force_N(rows["time"] - h, spindle_rpm, force_N)
    if record_control:
        tracking["control_V"] = rows["NpidServo.control_V"]
    name = "simulated tracking test" + ("" if completed else
                                        f" (interrupted at t = {rows['time'][-1]:g} s)")
    settled = rows["time"] > SETTLE_S
    error_mm = np.abs(rows["NpidServo.tracking_error_mm"][settled])
    figures = {"max_tracking_error_mm": float(error_mm.max()) if error_mm.size else math.nan,
               "rms_tracking_error_mm": float(np.sqrt(np.mean(error_mm**2)))
               if error_mm.size else math.nan}
    every = max(1, math.ceil(rows.size / TRACKING_SERIES_POINTS))
    series = Series("time_s", rows["time"][every - 1::every], "tracking_error_mm",
                    rows["NpidServo.tracking_error_mm"][every - 1::every], ("tracking",))
    summary = {"controller": controller, "frequency_hz": frequency_hz,
               "amplitude_mm": amplitude_mm, "spindle_rpm": spindle_rpm,
               "simulated_s": float(rows["time"][-1]), **figures}
    return ScenarioRun(name, overrides, {"tracking": tracking}, figures, series, summary,
                       completed)


def simulate_tracking(out, master, frequency_hz, amplitude_mm, duration_s, controller="pid",
                      spindle_rpm=None, force_N=CUTTING_FORCE_N, parameters=None, progress=None,
                      noise=None, record_control=False):
    """Sinusoidal tracking (:func:`run_tracking`) written as tracking.csv into the case
    folder ``out``; return the case folder, the run's settings and its max and RMS
    tracking error (mm)."""
    run = run_tracking(master, frequency_hz, amplitude_mm, duration_s, controller,
                       spindle_rpm, force_N, parameters, progress, record_control)
    return write_run(out, master, run, noise)


RUNS = {"iso230": run_iso230, "thermal": run_thermal, "tracking": run_tracking}


@dataclass(frozen=True)
class MeasurementNoise:
    """White Gaussian noise added to what a case records as measured (the positioning
    deviation, the tracking ``actual_mm``), standard deviation ``sigma_um``, drawn by
    ``numpy.random.default_rng(seed)``: the simulated axis measured by an instrument."""

    sigma_um: float
    seed: int = 0

    def __post_init__(self):
        if not (math.isfinite(self.sigma_um) and self.sigma_um >= 0):
            raise ParameterError(f"must be a finite number >= 0 (µm), got {self.sigma_um}",
                                 parameter="--noise-um")

    def measured(self, tables):
        """``tables`` with the noise added to their measured column."""
        rng = np.random.default_rng(self.seed)
        noisy = dict(tables)
        for table, kind in kinds().items():
            column, mm_per_um = kind.measured_column
            if table in tables:
                measured = np.asarray(tables[table][column], dtype=float)
                noisy[table] = {**tables[table], column: measured
                                + mm_per_um * rng.normal(0.0, self.sigma_um, measured.size)}
        return noisy


def check_axis_ranges(system):
    """Refuse, before anything is simulated, an FMU parameter the simulated case's axis.toml
    would hold (:data:`~feedaxis.fmu_map.AXIS_KEYS`) beyond any physical axis: the case
    format's ranges, naming ``Component.parameter``."""
    for table in AXIS_KEYS.values():
        for component in system.components:
            for key in table.get(component.fmu, ()):
                value = component.parameters.get(key)
                if isinstance(value, (int, float)) and not isinstance(value, bool):
                    problem = range_problem(key, value)
                    if problem:
                        raise InputError(f"{value:g} {problem} (axis.toml of the simulated "
                                         "case)", parameter=f"{component.name}.{key}")


def _readable(staged):
    """Refuse a simulated case the case reader would refuse (parameter values beyond any
    physical axis, such as --set GeometricError.offset_um=1e300), naming the file, row and
    column it would break, before it is published."""
    try:
        read_case(staged)
    except CaseError as error:
        where = ", ".join([error.path.name] + ([f"row {error.row}"] if error.row else [])
                          + ([f"column '{error.column}'"] if error.column else []))
        raise InputError(f"the simulated case would not be readable ({where}: "
                         f"{error.message}): a parameter value (--set, --model) beyond what "
                         "a case can hold (docs/bad-input.md)", parameter="--set") from None


def write_run(out, master, run, noise=None):
    """Write ``run`` as the case folder ``out``, its measured column with ``noise`` (a
    :class:`MeasurementNoise`) when given; return its summary with the folder. The summary's
    figures are the simulated axis's, before the noise.

    Raises
    ------
    ScenarioInterrupted
        After writing an interrupted run, saying what it holds.
    """
    with_servo = "tracking" in run.tables
    tables = noise.measured(run.tables) if noise else run.tables
    write_case(out, axis_values(master, run.parameters, run.name, with_servo=with_servo),
               **tables, check=_readable)
    summary = {"case": str(out), **run.summary}
    if noise:
        summary["noise"] = {"sigma_um": noise.sigma_um, "seed": noise.seed}
    if not run.completed:
        if with_servo:
            raise ScenarioInterrupted(f"interrupted at t = {summary['simulated_s']:g} s; the "
                                      f"partial tracking.csv is in {out}")
        raise ScenarioInterrupted(f"interrupted: {summary['samples']} of "
                                  f"{summary['planned_samples']} samples written to {out}")
    return summary


def _check_loop_budget(macro_step_s, stop_s, loop_step_s):
    """Refuse a tracking test whose case no reader would take: samples every macro step too
    far apart for the control loop, or a record too long for it
    (:func:`feedaxis.physics.servo.loop_budget_problem`)."""
    if macro_step_s / loop_step_s > MAX_INTERVAL_STEPS:
        steps = macro_step_s / loop_step_s
        raise ParameterError(f"a sample every {macro_step_s:g} s is {steps:.3g} "
                             f"steps of the {loop_step_s:g} s control loop; a tracking case may "
                             f"hold at most {MAX_INTERVAL_STEPS:g} between samples", "--step-ms")
    if stop_s / loop_step_s > MAX_LOOP_STEPS:
        raise ParameterError(f"{stop_s:g} s is {stop_s / loop_step_s:.3g} steps of the "
                             f"{loop_step_s:g} s control loop; a tracking case may need at most "
                             f"{MAX_LOOP_STEPS:g} ({MAX_LOOP_STEPS * loop_step_s:g} s)",
                             "duration_s")


def _positioning_parameters(parameters):
    """:data:`POSITIONING_SERVO` under the caller's values (theirs win)."""
    parameters = dict(parameters or {})
    for component, defaults in POSITIONING_SERVO.items():
        parameters[component] = {**defaults, **parameters.get(component, {})}
    return parameters


def axis_values(master, parameters, name, with_servo=False):
    """axis.toml content from the co-simulated axis's effective parameter values; with
    ``with_servo`` the ``[servo]`` table too (the controller as set in NpidServo, not its
    plant or friction: those are what a fit of the tracking case identifies)."""
    system = master.system.with_parameters(parameters or {})

    def values(component, keys):
        c = system.component(component)
        variables = master.loaded[c.fmu].variables
        return {k: c.parameters[k] if k in c.parameters else start_value(variables[k]) for k in keys}

    axis = {"name": name, **{table: axis_table(table, values) for table in AXIS_KEYS}}
    if with_servo:
        axis["servo"] = servo_from_fmu(values("NpidServo", [*SERVO_KEYS.values(), "nonlinear"]))
    return axis


def axis_table(table, values):
    """axis.toml ``[table]`` from the FMUs that take its keys (:data:`AXIS_KEYS`); a key
    several FMUs take must have one value in all of them."""
    found = {}
    for fmu, keys in AXIS_KEYS[table].items():
        for key, value in values(fmu, keys).items():
            found.setdefault(key, {})[fmu] = value
    differ = {key: by_fmu for key, by_fmu in found.items() if len(set(by_fmu.values())) > 1}
    if differ:
        by_fmu = next(iter(differ.values()))
        raise ParameterError(f"{' and '.join(by_fmu)} disagree on {', '.join(differ)}: one "
                             f"axis has one {table}", "--set")
    return {key: next(iter(by_fmu.values())) for key, by_fmu in found.items()}


def _positioning_columns(samples, rows, with_time=False):
    target_mm = np.array([s.target_mm for s in samples])
    columns = {"target_mm": target_mm,
               "error_um": (rows["table_position_mm"] - target_mm) * 1e3,
               "direction": [s.direction for s in samples], "run": [s.run for s in samples]}
    if with_time:
        columns["time_s"] = [s.time_s for s in samples]
        columns["ambient_C"] = rows["ambient_C"]
    return columns


def _positioning_summary(positioning, planned):
    error_um = positioning["error_um"]
    return {"samples": len(positioning["target_mm"]), "planned_samples": len(planned),
            **_deviation_range(error_um)}


def _deviation_range(error_um):
    return {"error_min_um": float(np.min(error_um)), "error_max_um": float(np.max(error_um))}


def _numbers(figures):
    """The figures that are measurements (µm), not counts of targets or runs."""
    return {name: value for name, value in figures.items() if name.endswith("_um")}


def _mean_deviation_series(target_mm, error_um, direction):
    """Mean deviation at each target (x̄_i↑ then x̄_i↓ of ISO 230-2) against the target."""
    xs, ys, groups = [], [], []
    for label, sign in (("+", 1.0), ("-", -1.0)):
        if np.any(direction == sign):
            targets, mean_um, _, _ = per_target(target_mm, error_um, direction, sign)
            xs.append(targets)
            ys.append(mean_um)
            groups += [label] * targets.size
    return Series("target_mm", np.concatenate(xs), "mean_deviation_um", np.concatenate(ys),
                  tuple(groups))


def _stop_time_s(duration_s, macro_step_s):
    """``duration_s`` rounded up to whole macro steps; refused beyond :data:`MAX_MACRO_STEPS`
    (a feed near 0 or a step near 0 would otherwise run for ever)."""
    steps = duration_s / macro_step_s
    if not steps <= MAX_MACRO_STEPS:
        raise ParameterError(f"the run would take {duration_s:.4g} s in {steps:.4g} macro steps "
                             f"of {macro_step_s:g} s, more than the {MAX_MACRO_STEPS:.0e} "
                             "feedaxis simulates; check the feed, the targets and --step-ms",
                             "duration")
    return math.ceil(steps - 1e-9) * macro_step_s


def _require_positive(**values):
    for name, value in values.items():
        require_positive(name, value)
