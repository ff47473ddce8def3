"""Circular tests for the known answers: simulated on the co-simulated machine, or written
from closed forms."""
import numpy as np

from feedaxis.case import read_case, write_case
from feedaxis.cosim.circular import simulate_circular
from feedaxis.cosim.machine import machine_from_case_axes
from feedaxis.cosim.master import Master
from feedaxis.cosim.scenarios import MeasurementNoise
from feedaxis.case import Axis
from feedaxis.circular_case import CircularTest, Machine

RADIUS_MM, FEED_MM_MIN, CENTER_MM = 20.0, 1000.0, (60.0, 40.0)


def machine(motor=False, servo=None):
    """Axes X (lead 10 mm) and Y (lead 5 mm) of a machine, every catalog effect off."""
    motors = {"step_angle_deg": 1.8, "error_period_steps": 4} if motor else {}
    return Machine("test machine", CircularTest(("X", "Y"), RADIUS_MM, FEED_MM_MIN, CENTER_MM),
                   {"X": Axis("X", {"lead_mm": 10.0}, dict(motors), dict(servo or {})),
                    "Y": Axis("Y", {"lead_mm": 5.0}, dict(motors), dict(servo or {}))})


def simulated_case(folder, fmu_paths, parameters=None, squareness_urad=0.0,
                   directions=(1, -1), noise_um=0.0, seed=1, samples_per_turn=1000,
                   motor=False, servo=None):
    """Simulate the circular test of :func:`machine` (with ``servo`` as both axes'
    ``[servo]``) with ``parameters`` ({component: {parameter: value}}) and read it back as
    a case."""
    system = machine_from_case_axes(machine(motor, servo), squareness_urad)
    with Master(system, fmu_paths) as master:
        simulate_circular(folder, master, MeasurementNoise(noise_um, seed) if noise_um else None,
                          radius_mm=RADIUS_MM, feed_mm_min=FEED_MM_MIN, center_mm=CENTER_MM,
                          directions=directions, samples_per_turn=samples_per_turn,
                          parameters=parameters)
    return read_case(folder)


def circle_columns(samples_per_turn=720, directions=(1, -1), feed_mm_min=FEED_MM_MIN):
    """circular.csv columns of an ideal test: each direction one turn from 0°, evenly
    spaced, timed at the feed (the clock runs on through both directions)."""
    step_deg = 360.0 / samples_per_turn
    seconds_per_deg = np.radians(RADIUS_MM) / (feed_mm_min / 60.0)
    angle = np.concatenate([np.mod(d * np.arange(samples_per_turn) * step_deg, 360.0)
                            for d in directions])
    direction = np.repeat(np.asarray(directions, float), samples_per_turn)
    time_s = np.arange(angle.size) * step_deg * seconds_per_deg
    return {"angle_deg": angle, "direction": direction, "time_s": time_s}


def synthetic_case(folder, deviation_um, columns, motor=False, servo=None):
    """Write and read a circular case of :func:`machine` (``servo`` both axes' ``[servo]``)
    with ``deviation_um`` at the samples of ``columns`` (:func:`circle_columns`)."""
    test = machine(motor, servo)
    axes = {name: {"screw": dict(a.screw), **({"motor": dict(a.motor)} if a.motor else {}),
                   **({"servo": dict(a.servo)} if a.servo else {})}
            for name, a in test.axes.items()}
    axis_values = {"name": test.name, "circular": {
        "axes": list(test.circular.axes), "radius_mm": RADIUS_MM, "feed_mm_min": FEED_MM_MIN,
        "center_mm": list(CENTER_MM)}, "axes": axes}
    write_case(folder, axis_values, circular={
        "angle_deg": columns["angle_deg"], "deviation_um": deviation_um,
        "direction": columns["direction"], "time_s": columns["time_s"]})
    return read_case(folder)
