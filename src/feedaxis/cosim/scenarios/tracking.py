"""The tracking kind's simulated test: ``feedaxis simulate tracking``.

:func:`simulate_tracking`: sinusoidal tracking (Anang et al. 2017, "Tracking
performance of NPID controller for cutting force disturbance of ball screw drive") ->
``axis.toml`` with ``[servo]`` + ``tracking.csv``; it writes what :func:`run_tracking` returns.
:data:`SCENARIOS` declares it to the tracking kind (``Tracking.scenarios``), with its
command-line options.
"""
from __future__ import annotations

import math

import numpy as np

from ...case import PHYSICAL_RANGE
from ...errors import ParameterError
from ...physics.servo import MAX_INTERVAL_STEPS, MAX_LOOP_STEPS, ServoParams
from ..master import SimulationInterrupted
from .base import (Scenario, ScenarioInterrupted, ScenarioRun, Series,
                   require_positive_values as _require_positive, stop_time_s, write_run)

SETTLE_S = 1.0
MAX_TRAVEL_MM = PHYSICAL_RANGE["reference_mm"][1]  # beyond any physical axis
TEETH = 2
# F0 (N) calibrated on one row of Anang et al. 2017 Table 2 (PID, 0.4 Hz, 10 mm, 1500 rpm:
# 0.0757 mm)
# with the assumed force_constant_N_per_V = 100; it then gives 0.2211 mm at 0.7 Hz, 20 mm,
# 1500 rpm (paper 0.2217), but falls faster with spindle speed than the paper.
CUTTING_FORCE_N = 1.4
TRACKING_SERIES_POINTS = 200  # tracking-error samples a sweep keeps per trial for its bands


def cutting_force_N(time_s, spindle_rpm, force_N, teeth=TEETH):
    """Milling force at the tooth-passing frequency, an assumption (Anang et al.
    2017 give none).

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
        Adds the cutting force of :func:`cutting_force_N` (1500/2500/3500 rpm in
        Anang et al. 2017).
    force_N : float
        Cutting-force amplitude F0 at 1500 rpm (N); see :data:`CUTTING_FORCE_N`.
    record_control : bool
        Write the controller output as tracking.csv's ``control_V``, as a drive records it.

    Returns
    -------
    ScenarioRun
        Figures: ``max_tracking_error_mm`` and ``rms_tracking_error_mm`` over t > 1 s (after
        the start-up transient, as the Anang et al. 2017 Table 1 reproduction); series: the
        tracking error against time at :data:`TRACKING_SERIES_POINTS` evenly spaced steps.
    """
    h = master.system.macro_step_s
    _check_reference(h, frequency_hz, amplitude_mm, duration_s)
    if controller not in ("pid", "npid", "cascade"):
        raise ParameterError(f"must be pid, npid or cascade, got {controller!r}", "controller")
    overrides = {**(parameters or {})}
    overrides["NpidServo"] = {**overrides.get("NpidServo", {}), "nonlinear": False,
                              "controller": controller}
    stop_s = stop_time_s(duration_s, h)
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
    figures, series = _tracking_figures(rows)
    summary = {"controller": controller, "frequency_hz": frequency_hz,
               "amplitude_mm": amplitude_mm, "spindle_rpm": spindle_rpm,
               "simulated_s": float(rows["time"][-1]), **figures}
    stopped = "" if completed else (f"interrupted at t = {summary['simulated_s']:g} s; the "
                                    "partial tracking.csv is in")
    return ScenarioRun(name, overrides, {"tracking": tracking}, figures, series, summary,
                       stopped, with_servo=True)


def _check_reference(macro_step_s, frequency_hz, amplitude_mm, duration_s):
    """Refuse a reference no axis could follow or no record could show: beyond any travel,
    at or above the macro step's Nyquist frequency, or over before the start-up transient."""
    _require_positive(frequency_hz=frequency_hz, amplitude_mm=amplitude_mm,
                      duration_s=duration_s)
    if amplitude_mm > MAX_TRAVEL_MM:
        raise ParameterError(f"must be <= {MAX_TRAVEL_MM:g} mm (beyond any physical axis), "
                             f"got {amplitude_mm:g}", "amplitude_mm")
    if frequency_hz >= 0.5 / macro_step_s:
        raise ParameterError(f"must be below {0.5 / macro_step_s:g} Hz, the Nyquist frequency "
                             f"of the {macro_step_s:g} s macro step, got {frequency_hz:g}",
                             "frequency_hz")
    if not duration_s > SETTLE_S:
        raise ParameterError(f"must exceed {SETTLE_S:g} s: the tracking error is measured "
                             f"after the first {SETTLE_S:g} s (the start-up transient), got "
                             f"{duration_s:g}", "duration_s")


def _tracking_figures(rows):
    """(figures, series) of a run's rows: the largest and RMS tracking error after
    :data:`SETTLE_S` (mm), and the tracking error at :data:`TRACKING_SERIES_POINTS` steps."""
    settled = rows["time"] > SETTLE_S
    error_mm = np.abs(rows["NpidServo.tracking_error_mm"][settled])
    figures = {"max_tracking_error_mm": float(error_mm.max()) if error_mm.size else math.nan,
               "rms_tracking_error_mm": float(np.sqrt(np.mean(error_mm**2)))
               if error_mm.size else math.nan}
    every = max(1, math.ceil(rows.size / TRACKING_SERIES_POINTS))
    series = Series("time_s", rows["time"][every - 1::every], "tracking_error_mm",
                    rows["NpidServo.tracking_error_mm"][every - 1::every], ("tracking",))
    return figures, series


def simulate_tracking(out, master, frequency_hz, amplitude_mm, duration_s, controller="pid",
                      spindle_rpm=None, force_N=CUTTING_FORCE_N, parameters=None, progress=None,
                      noise=None, record_control=False):
    """Sinusoidal tracking (:func:`run_tracking`) written as tracking.csv into the case
    folder ``out``; return the case folder, the run's settings and its max and RMS
    tracking error (mm)."""
    run = run_tracking(master, frequency_hz, amplitude_mm, duration_s, controller,
                       spindle_rpm, force_N, parameters, progress, record_control)
    return write_run(out, master, run, noise)


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


def _tracking_options(parser):
    parser.add_argument("--frequency-hz", type=float, default=0.4, help="default 0.4")
    parser.add_argument("--amplitude-mm", type=float, default=10.0, help="default 10")
    parser.add_argument("--duration-s", type=float, default=10.0, help="default 10")
    parser.add_argument("--controller", choices=("pid", "npid", "cascade"), default="pid",
                        help="pid or npid (Anang et al. 2017), or cascade: a drive's P "
                             "position loop around a velocity loop (its gains: --set "
                             "NpidServo.kp_per_s=..., kv_V_s_per_mm, tn_s, "
                             "velocity_feedforward)")
    parser.add_argument("--record-control", action="store_true",
                        help="write the controller output as tracking.csv's control_V, as a "
                             "drive records it")
    parser.add_argument("--spindle-rpm", type=float, help="e.g. 1500, 2500, 3500")
    parser.add_argument("--force-N", type=float,
                        help="cutting force F0 at 1500 rpm (default 1.4 N: fitted to one "
                             "row of Table 2 of Anang et al. 2017)")


def _tracking_arguments(args):
    force = {} if args.force_N is None else {"force_N": args.force_N}
    return {"frequency_hz": args.frequency_hz, "amplitude_mm": args.amplitude_mm,
            "duration_s": args.duration_s, "controller": args.controller,
            "spindle_rpm": args.spindle_rpm, "record_control": args.record_control, **force}


def _tracking_line(args, summary):
    force = f", cutting force at {args.spindle_rpm:g} rpm" if args.spindle_rpm else ""
    return (f"{args.out}/tracking.csv: {args.controller.upper()}, {args.frequency_hz:g} Hz, "
            f"{args.amplitude_mm:g} mm{force}; after the first second: max tracking error "
            f"{summary['max_tracking_error_mm']:.4f} mm, RMS "
            f"{summary['rms_tracking_error_mm']:.4f} mm")


SCENARIOS = (
    Scenario("tracking", run_tracking, _tracking_options, _tracking_arguments, _tracking_line,
             help="sinusoidal tracking, PID, NPID (Anang et al. 2017) or a cascade drive "
                  "-> tracking.csv",
             description="Reference A sin(2 pi f t); prints the maximum and RMS tracking error "
                         "after the first second. --spindle-rpm adds a milling force at the "
                         "tooth-passing frequency (mean force ~ 1500/rpm; an assumption, Anang "
                         "et al. 2017 publish none). axis.toml gets the [servo] table (the "
                         "controller), not the plant or friction: --set "
                         "NpidServo.friction_N=1 hides a Coulomb friction for `feedaxis "
                         "diagnose OUT` to find (docs/tracking.md)."),
)
