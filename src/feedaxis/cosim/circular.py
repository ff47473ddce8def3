"""The circular test (ISO 230-4) on the co-simulated machine, written as a ballbar records it.

Each direction is one run of the machine (:mod:`.machine`) from standing at the start of
its lead-in arc. The instrument's pivot sits at the nominal centre; the deviation of a
sample is the distance of the table point (both axes' ``table_position_mm``, squareness
included) from the pivot less the nominal radius, exactly (not linearised), and its angle
is the commanded angle at that instant, as a ballbar assigns angles from the programmed
feed. Samples are taken every ``360 / samples_per_turn`` degrees of the measured turn
(rounded to the macro step). :data:`SCENARIOS` declares the test to the circular kind
(``Circular.scenarios``): ``feedaxis simulate circular`` with its command-line options.
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError, number_list
from ..fmu_map import AXIS_KEYS, SERVO_KEYS, servo_from_fmu
from ..iso230_4 import circular_figures
from ..physics.circle import LEAD_IN_DEG, CircleInterpolator
from .machine import circular_machine, component_name
from .master import SimulationInterrupted
from .physics_check import start_value
from .scenarios.base import (Scenario, ScenarioInterrupted, ScenarioRun, Series, axis_table,
                             write_run)

DIRECTIONS = {"both": (1, -1), "ccw": (1,), "cw": (-1,)}


def run_circular(master, radius_mm=100.0, feed_mm_min=1000.0, center_mm=(0.0, 0.0),
                 directions=(1, -1), samples_per_turn=3600, lead_in_deg=LEAD_IN_DEG,
                 lead_out_deg=45.0, start_deg=0.0, parameters=None, progress=None):
    """Simulate a circular test in memory.

    Parameters
    ----------
    master : Master
        Running a machine system (:func:`feedaxis.cosim.machine.machine_system`).
    radius_mm, feed_mm_min : float
        Nominal radius (mm) and programmed feed along the circle (mm/min).
    center_mm : (float, float)
        Centre of the circle, machine coordinates of the two axes (mm).
    directions : sequence of {+1, -1}
        The runs, in order: +1 counter-clockwise, -1 clockwise.
    samples_per_turn : int
        Samples over the measured turn of each direction.
    lead_in_deg, lead_out_deg, start_deg : float
        The arcs before and after the measured turn, and where it starts (deg).
    parameters : dict, optional
        {component: {parameter: value}} for this run.

    Returns
    -------
    ScenarioRun
        ``tables["circular"]``: circular.csv's columns; figures: the ISO 230-4 figures;
        series: the deviation against the angle per direction.
    """
    axes = [v.name[:-len("_position_ref_mm")] for v in master.system.inputs
            if v.name.endswith("_position_ref_mm")]
    parts, elapsed_s, completed = [], 0.0, True
    for direction in directions:
        path = CircleInterpolator(radius_mm, feed_mm_min, tuple(center_mm), direction,
                                  start_deg, lead_in_deg, lead_out_deg)
        rows, completed = run_path(master, path, axes, parameters, progress)
        parts.append(_samples(rows, path, axes, samples_per_turn, elapsed_s))
        elapsed_s += path_stop_s(path, master.system.macro_step_s)
        if not completed:
            break
    columns = {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
    if columns["angle_deg"].size < 3:
        raise ScenarioInterrupted("interrupted before the measured turn; nothing written")
    figures = circular_figures(columns["angle_deg"], columns["deviation_um"],
                               columns["direction"]).as_dict()
    name = f"simulated circular test R{radius_mm:g} F{feed_mm_min:g}" + (
        "" if completed else " (interrupted)")
    series = Series("angle_deg", columns["angle_deg"], "deviation_um", columns["deviation_um"],
                    tuple("ccw" if d > 0 else "cw" for d in columns["direction"]))
    summary = {"samples": int(columns["angle_deg"].size),
               "directions": ["ccw" if d > 0 else "cw" for d in directions],
               **{k: v for k, v in figures.items() if v is not None}}
    circular = {"axes": axes, "radius_mm": float(radius_mm), "feed_mm_min": float(feed_mm_min),
                "center_mm": [float(c) for c in center_mm]}
    stopped = "" if completed else f"interrupted: {summary['samples']} samples written to"
    return ScenarioRun(name, {"parameters": parameters or {}, "circular": circular},
                       {"circular": columns}, figures, series, summary, stopped)


def path_stop_s(path, macro_step_s):
    """The macro steps (s) that cover ``path`` with its lead-in and lead-out arcs."""
    return np.ceil(path.duration_s / macro_step_s - 1e-9) * macro_step_s


def run_path(master, path, axes, parameters=None, progress=None):
    """Rows of every macro step along ``path`` (and whether it ran to the end)."""
    h = master.system.macro_step_s
    inputs = {f"{axis}_position_ref_mm": (lambda t, i=i: path.position_mm(t + h, i))
              for i, axis in enumerate(axes)}
    try:
        return master.run(float(path_stop_s(path, h)), inputs, parameters,
                          progress=progress), True
    except SimulationInterrupted as stopped:
        return stopped.partial, False


def _samples(rows, path, axes, samples_per_turn, elapsed_s):
    """circular.csv columns of one direction: the rows of the measured turn at the angles
    nearest to ``samples_per_turn`` equal steps."""
    time_s = rows["time"]
    start_s, end_s = path.measured_s
    wanted_s = start_s + (end_s - start_s) * np.arange(samples_per_turn) / samples_per_turn
    index = np.unique(np.searchsorted(time_s, wanted_s - 1e-9))
    index = index[(index < time_s.size) & (time_s[np.minimum(index, time_s.size - 1)] < end_s)]
    at = rows[index]
    angle = path.angle_deg(at["time"])
    centre = path.center_mm
    dx = at[f"{axes[0]}_table_position_mm"] - centre[0]
    dy = at[f"{axes[1]}_table_position_mm"] - centre[1]
    return {"angle_deg": np.mod(angle, 360.0),
            "deviation_um": (np.hypot(dx, dy) - path.radius_mm) * 1e3,
            "direction": np.full(index.size, float(path.direction)),
            "time_s": at["time"] + elapsed_s}


def machine_axis_values(master, run):
    """axis.toml of the simulated circular test: ``[circular]`` and, per axis, the
    ``[screw]`` (and ``[motor]`` where the axis has a StepperError) its FMUs ran with, and
    its ``[servo]`` where its controller was given (a ``[servo]`` of ``--machine``, or
    ``--set X_NpidServo.controller``): the controller, not the plant or friction."""
    system = master.system.with_parameters(run.parameters["parameters"])
    names = {c.name for c in system.components}
    axes = {}
    for axis in run.parameters["circular"]["axes"]:
        def values(fmu, keys, axis=axis):
            component = system.component(component_name(axis, fmu))
            variables = master.loaded[component.fmu].variables
            return {k: component.parameters.get(k, start_value(variables[k])) for k in keys}

        tables = {"screw": axis_table("screw", lambda fmu, keys: values(fmu, keys) if
                                      component_name(axis, fmu) in names else {})}
        if component_name(axis, "StepperError") in names:
            tables["motor"] = values("StepperError", AXIS_KEYS["motor"]["StepperError"])
        if "controller" in system.component(component_name(axis, "NpidServo")).parameters:
            tables["servo"] = servo_from_fmu(values("NpidServo",
                                                    [*SERVO_KEYS.values(), "nonlinear"]))
        axes[axis] = tables
    return {"name": run.name, "circular": run.parameters["circular"], "axes": axes}


def write_circular(out, master, run, noise=None):
    """Write the circular test ``run`` as the case folder ``out`` (axis.toml with
    ``[circular]`` and ``[axes.NAME]``, circular.csv); return its summary."""
    return write_run(out, master, run, noise, machine_axis_values(master, run))


def simulate_circular(out, master, noise=None, **options):
    """Simulate a circular test (:func:`run_circular`, ``options``) and write it as the case
    folder ``out`` (:func:`write_circular`)."""
    return write_circular(out, master, run_circular(master, **options), noise)


def _options(sub):
    sub.add_argument("--machine", metavar="AXIS",
                     help="axis.toml (or case folder) of a circular case: its axes, circle and "
                          "each axis's screw, motor and servo (default: axes X and Y with the "
                          "FMUs' defaults)")
    sub.add_argument("--radius-mm", type=float, help="nominal radius (default 100, or the "
                                                     "--machine's)")
    sub.add_argument("--feed-mm-min", type=float, help="programmed feed (default 1000, or the "
                                                       "--machine's)")
    sub.add_argument("--center-mm", metavar="C1,C2", help="centre in machine coordinates "
                                                          "(default R,R, or the --machine's)")
    sub.add_argument("--directions", choices=("both", "ccw", "cw"), default="both",
                     help="counter-clockwise then clockwise (default both)")
    sub.add_argument("--samples-per-turn", type=int, default=3600,
                     help="samples over the measured turn of each direction (default 3600)")
    sub.add_argument("--lead-in-deg", type=float, default=45.0,
                     help="arc travelled before the measured turn (default 45)")
    sub.add_argument("--squareness-urad", type=float, default=0.0,
                     help="out-of-squareness of the second axis towards the first, µrad "
                          "(default 0)")


def _machine(args):
    """(the machine system, the circle's keywords) of the command line's options."""
    return circular_machine(
        args.machine, args.radius_mm, args.feed_mm_min,
        number_list(args.center_mm, "--center-mm") if args.center_mm else None,
        args.squareness_urad, args.step_ms, args.thermal_step_s, args.set, args.model)


def _arguments(args):
    circle = _machine(args)[1]
    if args.samples_per_turn < 3:
        raise InputError(f"must be at least 3, got {args.samples_per_turn}",
                         parameter="--samples-per-turn")
    return {**circle, "directions": DIRECTIONS[args.directions],
            "samples_per_turn": args.samples_per_turn, "lead_in_deg": args.lead_in_deg}


def _line(args, summary):
    figures = ", ".join(f"{k[:-3]} {v:.3f}" for k, v in summary.items()
                        if k in ("G_um", "H_um", "F_max_um", "F_min_um"))
    return (f"{args.out}: {summary['samples']} samples ({', '.join(summary['directions'])}); "
            f"ISO 230-4 (µm): {figures}")


SCENARIOS = (
    Scenario("circular", run_circular, _options, _arguments, _line,
             help="circular test of two axes (ISO 230-4, ballbar) -> circular.csv",
             description="Two co-simulated axes (each NpidServo, GeometricError, StepperError, "
                         "ThermalScrew, components named X_NpidServo, ...) and their "
                         "squareness; an interpolator commands the circle at the feed, from "
                         "standing through a lead-in arc, one measured turn and a lead-out "
                         "arc, in each direction; the case records the radial deviation from "
                         "the nominal centre as a ballbar does (axis.toml with [circular] and "
                         "[axes.NAME], circular.csv).",
             system=lambda args: _machine(args)[0], write=write_circular, sweeps=False),
)
