"""Circular tests simulated on the co-simulated machine, for the circular tests' known answers."""
from feedaxis.case import read_case
from feedaxis.cosim.circular import simulate_circular
from feedaxis.cosim.machine import machine_from_case_axes
from feedaxis.cosim.master import Master
from feedaxis.cosim.scenarios import MeasurementNoise
from feedaxis.case import CircularTest, Machine, Axis

RADIUS_MM, FEED_MM_MIN, CENTER_MM = 20.0, 1000.0, (60.0, 40.0)


def machine(motor=False, servo=None):
    """Axes X (lead 10 mm) and Y (lead 5 mm) of a machine, every catalog effect off."""
    motors = {"step_angle_deg": 1.8, "error_period_steps": 4} if motor else {}
    return Machine("test machine", CircularTest(("X", "Y"), RADIUS_MM, FEED_MM_MIN, CENTER_MM),
                   {"X": Axis("X", {"lead_mm": 10.0}, dict(motors), dict(servo or {})),
                    "Y": Axis("Y", {"lead_mm": 5.0}, dict(motors), dict(servo or {}))})


def simulated_case(folder, fmu_paths, parameters=None, squareness_urad=0.0,
                   directions=(1, -1), noise_um=0.0, seed=1, samples_per_turn=1000,
                   motor=False):
    """Simulate the circular test of :func:`machine` with ``parameters``
    ({component: {parameter: value}}) and read it back as a case."""
    system = machine_from_case_axes(machine(motor), squareness_urad)
    with Master(system, fmu_paths) as master:
        simulate_circular(folder, master, MeasurementNoise(noise_um, seed) if noise_um else None,
                          radius_mm=RADIUS_MM, feed_mm_min=FEED_MM_MIN, center_mm=CENTER_MM,
                          directions=directions, samples_per_turn=samples_per_turn,
                          parameters=parameters)
    return read_case(folder)
