"""The positioning kind's simulated tests: ``feedaxis simulate iso230`` and ``thermal``.

- :func:`simulate_iso230`: ISO 230-2 positioning cycle -> ``axis.toml`` + ``positioning.csv``
  (+ ``duty.csv``, the motion simulated);
- :func:`simulate_thermal`: a duty cycle with measurement passes -> + ``duty.csv``.

Each writes what its in-memory twin (:func:`run_iso230`, :func:`run_thermal`) returns, a
:class:`~.base.ScenarioRun`; :data:`SCENARIOS` declares both to the positioning kind
(``Positioning.scenarios``), with their command-line options.

Every motion is a sequence of :class:`~feedaxis.physics.thermal.DutySegment` (travel between
two points at a feed, or standing still), the same segments duty.csv holds, so what the
thermal scenario writes is exactly the motion it simulated. The servo's reference input
k is the motion at t_{k+1}: NpidServo ramps its reference linearly over each communication
step, so it then follows the motion without the one-step delay of a held sample.

A measured deviation is what a laser interferometer sees: table position - target, with
the table position = servo position + the three FMUs' errors (``table_position_mm``).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...compensate import thermal_error_um
from ...errors import ParameterError, number_list
from ...iso230 import iso230_figures, per_target
from ...measurement.positioning import PositioningSamples
from ...physics.thermal import DutySegment
from ..master import SimulationInterrupted
from .base import (Scenario, ScenarioInterrupted, ScenarioRun, Series,
                   require_positive_values as _require_positive, stop_time_s, write_run)

ISO_REFERENCE_C = 20.0
MAX_SAMPLES = 100_000  # samples of one simulated test (ISO 230-2: 5 runs x 2 x ~20 targets)
# Positioning tests (iso230, thermal) run the servo with a type-1 plant (a0 = 0): with the
# a0 = 193.3 1/s² of Anang et al. 2017 and its tiny integral gain the loop keeps a static
# error of about
# target/364 (1.4 mm at 500 mm), which no CNC axis shows and which would swamp the errors
# a positioning test is about. Tracking keeps the published plant; --set overrides both.
POSITIONING_SERVO = {"NpidServo": {"plant_stiffness_per_s2": 0.0}}


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
    stop_s = stop_time_s(motion.time_s, h)
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
                       _positioning_summary(positioning, motion.samples),
                       _stopped(positioning, motion, completed))


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
                       _stopped(positioning, motion, completed))


def simulate_thermal(out, master, duty, targets_mm, every_s, feed_mm_min=3000.0,
                     dwell_s=0.5, parameters=None, progress=None, noise=None):
    """Simulate a thermal test (:func:`run_thermal`) and write duty.csv + positioning.csv
    into the case folder ``out``; return its summary."""
    run = run_thermal(master, duty, targets_mm, every_s, feed_mm_min, dwell_s, parameters,
                      progress)
    return write_run(out, master, run, noise)


def _positioning_parameters(parameters):
    """:data:`POSITIONING_SERVO` under the caller's values (theirs win)."""
    parameters = dict(parameters or {})
    for component, defaults in POSITIONING_SERVO.items():
        parameters[component] = {**defaults, **parameters.get(component, {})}
    return parameters


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


def _stopped(positioning, motion, completed):
    """What an interrupted run's case holds (:attr:`ScenarioRun.stopped`); empty if complete."""
    if completed:
        return ""
    return (f"interrupted: {len(positioning['target_mm'])} of {len(motion.samples)} samples "
            "written to")


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




def _add_motion_options(parser):
    parser.add_argument("--feed-mm-min", type=float, default=3000.0,
                        help="feed of the moves between targets (default 3000 mm/min)")
    parser.add_argument("--dwell-s", type=float, default=0.5,
                        help="dwell at each target before the sample (default 0.5 s)")


def _iso230_options(parser):
    parser.add_argument("--targets", type=int, default=11, help="number of targets (default 11)")
    parser.add_argument("--spacing-mm", type=float, default=50.0,
                        help="target spacing p (default 50)")
    parser.add_argument("--first-mm", type=float, default=0.0, help="P_1 before offset (default 0)")
    parser.add_argument("--runs", type=int, default=5, help="runs each direction (default 5)")
    parser.add_argument("--overrun-mm", type=float, default=2.0, help="default 2")
    _add_motion_options(parser)


def _iso230_arguments(args):
    return {"targets_mm": iso230_targets(args.targets, args.spacing_mm, args.first_mm),
            "runs": args.runs, "feed_mm_min": args.feed_mm_min, "dwell_s": args.dwell_s,
            "overrun_mm": args.overrun_mm}


def _iso230_line(args, summary):
    return (f"{args.out}: {summary['samples']} samples, {args.targets} targets x "
            f"{args.runs} runs each direction; deviation "
            f"{summary['error_min_um']:.3f} to {summary['error_max_um']:.3f} µm")


def _thermal_options(parser):
    parser.add_argument("--duty", required=True, metavar="duty.csv", help="the heating duty")
    parser.add_argument("--targets", required=True, metavar="X1,X2,...",
                        help="targets of each measurement pass (mm), visited in this order")
    parser.add_argument("--every-s", type=float, default=600.0,
                        help="duty time between measurement passes (default 600 s)")
    _add_motion_options(parser)


def _thermal_arguments(args):
    from ...case import read_duty

    return {"duty": read_duty(args.duty), "targets_mm": number_list(args.targets, "--targets"),
            "every_s": args.every_s, "feed_mm_min": args.feed_mm_min, "dwell_s": args.dwell_s}


def _thermal_line(args, summary):
    return (f"{args.out}: {summary['samples']} samples (duty.csv + positioning.csv); "
            f"deviation {summary['error_min_um']:.3f} to {summary['error_max_um']:.3f} µm")


SCENARIOS = (
    Scenario("iso230", run_iso230, _iso230_options, _iso230_arguments, _iso230_line,
             help="ISO 230-2 positioning test -> positioning.csv + duty.csv",
             description="Targets P_i = (i-1) p + r_i (r_i a different small offset at each), "
                         "RUNS runs approaching every target in + and in -, overrun beyond the "
                         "end targets, dwell, then the deviation table position - target; "
                         "duty.csv holds the motion simulated (it warms the screw), "
                         "positioning.csv the samples with their time."),
    Scenario("thermal", run_thermal, _thermal_options, _thermal_arguments, _thermal_line,
             help="duty cycle with measurement passes -> + duty.csv",
             description="Drive the axis through DUTY (duty.csv format) with a measurement pass "
                         "over --targets at t = 0, every --every-s of duty time and at the end; "
                         "write the motion as duty.csv and the samples (with time_s) as "
                         "positioning.csv."),
)
