"""The physics inside each FMU's step, in-process: the fast path against its reference.

Run: ``python benchmarks/bench_fmu_physics.py [--repeats 7] [--number 2000]``. It builds
the four FMUs, imports each slave from its unpacked resources (no FMI host: this measures
the Python work of ``step()`` alone, not the FMI calls; ``bench_fmi_floor.py`` measures
those) and times, side by side in this one run:

- ``slave.step()`` of each FMU at the default axis schedule (1 ms; the thermal screw 0.1 s),
- the physics call that step makes (the fast path),
- the same quantity through the reference path: the servo's kernel stepped 0.1 ms at a time
  (``run_loop``; numba-compiled too when numba imports), the algebraic FMUs' formulas on
  NumPy arrays of one element (``np.interp`` for the sag table), the thermal update with
  the dense rate matrix and source vector rebuilt every step and the elongation by
  ``np.interp`` on the cumulative field.

Each time is the median over ``--repeats`` repeats of ``--number`` calls, in µs per call;
the ratio is reference / fast.
"""
import argparse
import importlib
import statistics
import sys
import tempfile
import timeit
import zipfile
from pathlib import Path

import numpy as np

from feedaxis.fmu_build import build_fmus
from feedaxis.physics import geometry, motor, mounting, servo, thermal

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments  # noqa: E402

INPUTS = {"position_ref_mm": 5.0, "disturbance_N": 0.0, "position_mm": 5.0,
          "velocity_mm_s": 50.0, "ambient_C": 20.0}
STEP_S = {"NpidServo": 1e-3, "StepperError": 1e-3, "GeometricError": 1e-3, "ThermalScrew": 0.1}


def median_us(call, repeats, number):
    """Median over ``repeats`` of the mean cost of ``number`` calls (µs per call)."""
    return 1e6 * statistics.median(timeit.repeat(call, number=number, repeat=repeats)) / number


def load_slaves(folder):
    """{name: initialised slave with the benchmark's inputs}, imported from unpacked FMUs."""
    slaves = {}
    for path in build_fmus(Path(folder) / "fmus"):
        unpacked = Path(folder) / path.stem
        zipfile.ZipFile(path).extractall(unpacked)
        sys.path.insert(0, str(unpacked / "resources"))
        slave = getattr(importlib.import_module(path.stem), path.stem)(
            instance_name="bench", resources=str(unpacked / "resources"))
        slave.exit_initialization_mode()
        for name, value in INPUTS.items():
            if name in slave._input_names:
                setattr(slave, name, value)
        slaves[path.stem] = slave
    return slaves


def servo_paths():
    """(fast, reference, compiled reference or None) advancing the PID loop by 1 ms."""
    params = servo.ServoParams()
    fast = servo.Servo(params, 0.0)
    coefficients = servo.loop_coefficients(params)
    steps = round(STEP_S["NpidServo"] / params.time_step_s)
    state, buffer = [0.0] * servo.STATE_SIZE, [0.0] * params.buffer_size
    arrays = (np.array([steps]), np.array([5.0]), np.array([0.0]), np.zeros(servo.STATE_SIZE),
              np.zeros(params.buffer_size), np.zeros(1), np.zeros(1))
    try:
        compiled = servo.compiled_loop()
        compiled(coefficients, *arrays)  # compile (or load from the cache) outside the timing
    except ImportError:
        compiled = None
    coefficients_list = coefficients.tolist()
    return (lambda: fast.advance(STEP_S["NpidServo"], 5.0, 0.0),
            lambda: servo.run_loop(coefficients_list, [steps], [5.0], [0.0], state, buffer, [0.0],
                                   [0.0]),
            None if compiled is None else lambda: compiled(coefficients, *arrays))


def stepper_paths():
    """(fast, reference): the motor error at one float and at a one-element array."""
    period_mm = motor.motor_error_period_mm(1.0, 0.72, 10)
    one = np.array([5.0])
    return (lambda: motor.motor_error_um(5.0, period_mm, (0.08, 0.0), (0.06, 0.0)),
            lambda: motor.motor_error_um(one, period_mm, (0.08, 0.0), (0.06, 0.0)))


def geometric_paths():
    """(fast, reference): sag and transmission error at one float and a one-element array."""
    table = geometry.gravity_sag_table(0.8, 0.034, 7800.0, 2.1e11, "fixed-free")

    def error_um(position_mm):
        sag_um = geometry.gravity_sag_error_um(mounting.screw_coordinate_m(position_mm, -141.0),
                                               table)
        return geometry.transmission_error_um(position_mm, 1.0, 1.0, 0.2515, -0.5084, 0.2005,
                                              0.1504, 0.0, sag_um)

    one = np.array([5.0])
    return lambda: error_um(5.0), lambda: error_um(one)


def dense_thermal_step(params, rise_K, duration_s, position_mm, feed_mm_min):
    """The reference update: the dense rate matrix and sources rebuilt, θ + dt (A θ + s)."""
    nut = thermal.nut_cells(params.cells,
                            mounting.screw_coordinate_m(position_mm, params.fixed_end_mm))
    rates = thermal.rate_matrix(params, feed_mm_min, nut)
    sources = thermal.source_rate(params.cells, feed_mm_min, nut)
    return rise_K + duration_s * (rates @ rise_K + sources)


def thermal_paths():
    """(fast, reference): one 0.1 s update and the FMU's outputs from the field."""
    params = thermal.ThermalScrewParams()
    rise_K = np.linspace(2.0, 0.5, params.n_cells)
    nodes_m = np.arange(params.n_cells + 1) * params.cell_length_m

    def fast():
        field = thermal.advance(params, rise_K, STEP_S["ThermalScrew"], 5.0, 3000.0)
        return (thermal.thermal_error_um(params, field, 5.0),
                thermal.screw_elongation_um(params, field, params.length_m))

    def reference():
        field = dense_thermal_step(params, rise_K, STEP_S["ThermalScrew"], 5.0, 3000.0)
        cumulative_um = np.concatenate(([0.0], np.cumsum(params.expansion_per_K * field
                                                         * params.cell_length_m * 1e6)))
        screw_m = mounting.screw_coordinate_m(5.0, params.fixed_end_mm)
        return (np.interp(screw_m, nodes_m, cumulative_um),
                np.interp(params.length_m, nodes_m, cumulative_um))

    return fast, reference


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="repeats, median taken (default 7)")
    parser.add_argument("--number", type=int, default=2000,
                        help="calls per repeat (default 2000; a tenth for the thermal screw)")
    args = arguments(parser, argv, repeats=1, number=20)
    servo_fast, servo_stepped, servo_compiled = servo_paths()
    paths = {"NpidServo": (servo_fast, servo_stepped), "StepperError": stepper_paths(),
             "GeometricError": geometric_paths(), "ThermalScrew": thermal_paths()}
    with tempfile.TemporaryDirectory() as folder:
        slaves = load_slaves(folder)
        print(f"µs per call, median of {args.repeats} repeats of {args.number} calls "
              f"({args.number // 10} for ThermalScrew); ratio = reference / fast physics")
        print(f"{'FMU':<16}{'step()':>9}{'physics':>9}{'reference':>11}{'ratio':>7}  reference")
        labels = {"NpidServo": "run_loop stepped 10 x 0.1 ms",
                  "StepperError": "NumPy, one-element array",
                  "GeometricError": "NumPy, one-element array, np.interp",
                  "ThermalScrew": "dense A rebuilt, A @ θ, np.interp"}
        for name, (fast, reference) in paths.items():
            number = args.number // 10 if name == "ThermalScrew" else args.number
            slave = slaves[name]
            step_us = median_us(lambda: slave.step(STEP_S[name]), args.repeats, number)
            fast_us = median_us(fast, args.repeats, number)
            reference_us = median_us(reference, args.repeats, number)
            print(f"{name:<16}{step_us:>9.2f}{fast_us:>9.2f}{reference_us:>11.2f}"
                  f"{reference_us / fast_us:>7.1f}  {labels[name]}")
        if servo_compiled is not None:
            compiled_us = median_us(servo_compiled, args.repeats, args.number)
            print(f"{'':<16}{'':>9}{'':>9}{compiled_us:>11.2f}"
                  f"{compiled_us / median_us(servo_fast, args.repeats, args.number):>7.1f}"
                  f"  run_loop compiled by numba")


if __name__ == "__main__":
    sys.exit(main())
