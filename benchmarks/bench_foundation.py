"""Foundation benchmarks: FMU call overhead through fmpy, and the fast thermal solver.

Run: ``python benchmarks/bench_foundation.py [--repeats 5]``. Every figure is the median
of interleaved repeats measured in this one run, printed as a ratio.
"""
import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from feedaxis.cosim.fmu_runner import LoadedFmu
from feedaxis.fmu_build import AXIS_FMU_NAMES, build_fmus
from feedaxis.physics import geometry, motor, mounting, servo, thermal

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments  # noqa: E402

N_CALLS = 2000


def bare_calls():
    """Name -> (step size, one bare physics call doing one FMU step's work)."""
    loop = servo.Servo(servo.ServoParams())
    params = thermal.ThermalScrewParams()
    state = {"rise": np.zeros(params.n_cells)}
    sag = geometry.gravity_sag_table(0.8, 0.034, 7800.0, 2.1e11, "fixed-free")

    def thermal_step():
        state["rise"] = thermal.advance(params, state["rise"], 1.0, 200.0, 6000.0)
        return thermal.thermal_error_um(params, state["rise"], 200.0)

    def geometric_step():
        sag_um = geometry.gravity_sag_error_um(mounting.screw_coordinate_m(2.0, -141.0), sag)
        return geometry.transmission_error_um(2.0, 1.0, 1.0, 0.2515, -0.5084, 0.2005, 0.1504, 0.0, sag_um)

    return {"NpidServo": (1e-3, lambda: loop.advance(1e-3, 1.0)),
            "StepperError": (0.01, lambda: motor.motor_step_error_um(2.0, 1.0, 0.72, 10, (0.08, 0.0), (0.06, 0.0))),
            "GeometricError": (0.01, geometric_step),
            "ThermalScrew": (1.0, thermal_step)}


def time_fmu_calls(loaded, step_size_s):
    """Seconds per setReal + doStep + getReal through fmpy."""
    slave = loaded.instantiate("bench")
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    inputs = [v.valueReference for v in loaded.description.modelVariables if v.causality == "input"]
    outputs = [v.valueReference for v in loaded.description.modelVariables if v.causality == "output"]
    values = [1.0] * len(inputs)
    start = time.perf_counter()
    for k in range(N_CALLS):
        slave.setReal(inputs, values)
        slave.doStep(k * step_size_s, step_size_s)
        slave.getReal(outputs)
    elapsed = (time.perf_counter() - start) / N_CALLS
    slave.freeInstance()
    return elapsed


def time_bare(call):
    start = time.perf_counter()
    for _ in range(N_CALLS):
        call()
    return (time.perf_counter() - start) / N_CALLS


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5, help="interleaved repeats (default 5)")
    parser.add_argument("--minutes", type=float, default=168.0,
                        help="length of the Table 2 cycle simulated (default: all of it, 168)")
    args = arguments(parser, argv, repeats=1, minutes=6.0)
    repeats = args.repeats

    print(f"FMU call overhead: setReal+doStep+getReal through fmpy vs the bare physics call "
          f"(median of {repeats} x {N_CALLS} calls)")
    with tempfile.TemporaryDirectory() as folder:
        loaded = {p.stem: LoadedFmu(p) for p in build_fmus(folder, AXIS_FMU_NAMES)}
        bare = bare_calls()
        for name, fmu in loaded.items():
            step, call = bare[name]
            fmu_s, bare_s = [], []
            for _ in range(repeats):
                fmu_s.append(time_fmu_calls(fmu, step))
                bare_s.append(time_bare(call))
            f, b = statistics.median(fmu_s), statistics.median(bare_s)
            print(f"  {name:15s} fmpy {f * 1e6:8.1f} us  bare {b * 1e6:8.1f} us  "
                  f"overhead {(f - b) * 1e6:6.1f} us  ratio {f / b:5.2f}")
            fmu.close()

    print("\nThermal, Rong et al. 2023 Table 2 cycle (168 min), samples every 60 s: closed form vs "
          "straightforward explicit dt = 0.1 s")
    params = thermal.ThermalScrewParams()
    times = np.arange(0.0, args.minutes * 60.0 + 1.0, 60.0)
    for feed in (3000.0, 6000.0, 9000.0):
        segments = [s for s in thermal.table2_cycle(feed) if s.start_s < times[-1]]
        fast_s, slow_s = [], []
        for _ in range(max(1, repeats // 2)):
            start = time.perf_counter()
            fast = thermal.simulate_duty(params, segments, times)
            fast_s.append(time.perf_counter() - start)
            start = time.perf_counter()
            slow = thermal.explicit_duty(params, segments, times)
            slow_s.append(time.perf_counter() - start)
        positions = np.linspace(0.0, 500.0, 11)
        fast_um = np.array([thermal.thermal_error_um(params, fast, x) for x in positions])
        slow_um = np.array([thermal.thermal_error_um(params, slow, x) for x in positions])
        deviation = np.abs(fast_um - slow_um)
        significant = np.abs(slow_um) > 0.05 * np.max(np.abs(slow_um))
        f, s = statistics.median(fast_s), statistics.median(slow_s)
        print(f"  {feed:6.0f} mm/min  fast {f * 1e3:7.1f} ms  explicit {s:6.2f} s  speed-up {s / f:6.0f}x  "
              f"peak error {np.max(np.abs(slow_um)):5.1f} um  max deviation {np.max(deviation):.4f} um "
              f"({100 * np.max(deviation) / np.max(np.abs(slow_um)):.3f} % of peak, "
              f"{100 * np.max(deviation[significant] / np.abs(slow_um[significant])):.3f} % worst sample "
              f"above 5 % of peak)")


if __name__ == "__main__":
    main()
