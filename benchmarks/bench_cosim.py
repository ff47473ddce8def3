"""Co-simulation benchmark: the full axis, 10 s tracking at a 1 ms macro step.

Run: ``python benchmarks/bench_cosim.py [--repeats 5] [--stop-s 10]``. In one run, with
repeats interleaved, it times

- the project's master (feedaxis.cosim.master) running the four FMUs, end to end
  (extract, instantiate, 10 000 macro steps recording every output, free);
- OSP libcosim (libcosimpy) running the exported .ssp end to end (load, instantiate, the
  same 10 000 steps with the reference set by an override manipulator and the same outputs
  observed every step) -- the driver of tests/libcosim_driver.py;
- the master with every FMU call timed: the share of its stepping loop spent outside the
  FMUs' own fmi2SetReal/fmi2DoStep/fmi2GetReal calls. The timers cost time outside the
  calls they time (a Python call and two clock reads each, about as much as the master's
  own work per call): the master calibrates that cost per timed call in the same process
  (``Timing.timer_s``) and takes it out of the loop; the share with the timers left in is
  printed too (an upper bound).

It prints medians (and ranges) and the ratios of the medians.
"""
import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from feedaxis.cosim.master import Master
from feedaxis.cosim.ssp import export_ssp
from feedaxis.cosim.system import default_axis
from feedaxis.fmu_build import build_fmus

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from libcosim_driver import simulate_ssp_with_libcosim  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments, describe  # noqa: E402

OUTPUTS = ("NpidServo.position_mm", "NpidServo.velocity_mm_s", "NpidServo.tracking_error_mm",
           "StepperError.error_um", "GeometricError.error_um", "ThermalScrew.error_um",
           "ThermalScrew.elongation_um", "ThermalScrew.peak_rise_K")


def reference_mm(n_steps, h):
    """Anang et al. 2017 tracking: 20 mm at 0.7 Hz, one value per macro step."""
    return 20.0 * np.sin(2 * np.pi * 0.7 * np.arange(n_steps) * h)


def time_master(system, fmu_paths, stop_s, profile=False):
    """(end-to-end seconds, Timing of the run)."""
    reference = reference_mm(int(round(stop_s / system.macro_step_s)), system.macro_step_s)
    started = time.perf_counter()
    with Master(system, fmu_paths) as master:
        result = master.run(stop_s, {"position_ref_mm": reference}, profile=profile)
    elapsed = time.perf_counter() - started
    assert np.isfinite(result["table_position_mm"]).all()
    return elapsed, master.timing


def time_libcosim(ssp_path, system, stop_s):
    n_steps = int(round(stop_s / system.macro_step_s))
    started = time.perf_counter()
    result = simulate_ssp_with_libcosim(
        ssp_path, n_steps, {"NpidServo.position_ref_mm": reference_mm(n_steps, system.macro_step_s)},
        {}, OUTPUTS)
    elapsed = time.perf_counter() - started
    assert np.isfinite(result["NpidServo.position_mm"]).all()
    return elapsed


def time_libcosim_engine(ssp_path, stop_s):
    from libcosimpy.CosimExecution import CosimExecution

    started = time.perf_counter()
    execution = CosimExecution.from_ssp_file(str(ssp_path))
    assert execution.simulate_until(round(stop_s * 1e9))
    del execution
    return time.perf_counter() - started


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--stop-s", type=float, default=10.0)
    args = arguments(parser, argv, repeats=1, stop_s=0.05)
    system = default_axis()
    with tempfile.TemporaryDirectory() as folder:
        fmu_paths = {p.stem: p for p in build_fmus(Path(folder) / "fmus")}
        ssp_path = export_ssp(Path(folder) / "axis.ssp", system, fmu_paths)
        time_master(system, fmu_paths, 1.0)  # warm-up: first imports inside the FMUs
        master_s, libcosim_s, engine_s, loop_s, fmu_s, overhead, setup, timers, plain = (
            [] for _ in range(9))
        for _ in range(args.repeats):
            elapsed, timing = time_master(system, fmu_paths, args.stop_s)
            master_s.append(elapsed)
            plain.append(timing.loop_s)
            libcosim_s.append(time_libcosim(ssp_path, system, args.stop_s))
            engine_s.append(time_libcosim_engine(ssp_path, args.stop_s))
            _, timing = time_master(system, fmu_paths, args.stop_s, profile=True)
            loop_s.append(timing.loop_s)
            fmu_s.append(timing.fmu_s)
            overhead.append(timing.overhead_fraction)
            timers.append(timing.timer_s)
            setup.append(timing.wall_s - timing.loop_s)
    steps = int(round(args.stop_s / system.macro_step_s))
    print(f"full axis, {args.stop_s:g} s tracking (20 mm, 0.7 Hz), macro step "
          f"{system.macro_step_s * 1e3:g} ms = {steps} macro steps, thermal every "
          f"{system.ratio(system.component('ThermalScrew'))}; {args.repeats} interleaved repeats")
    print(f"  project master, end to end : {describe(master_s)}")
    print(f"  libcosim on the .ssp       : {describe(libcosim_s)}")
    ratio = statistics.median(master_s) / statistics.median(libcosim_s)
    print(f"  master / libcosim wall time: {ratio:.2f} (target <= 1)")
    print(f"  libcosim engine alone      : {describe(engine_s)}; master / engine "
          f"{statistics.median(master_s) / statistics.median(engine_s):.2f}")
    print(f"  master, profiled run       : stepping loop {describe(loop_s)}, FMU calls "
          f"{describe(fmu_s)}, setup (instantiate + initialise) {describe(setup)}")
    print(f"  master, plain run          : stepping loop {describe(plain)}")
    own = [(l - t - f) / steps for l, t, f in zip(loop_s, timers, fmu_s)]
    raw = [1 - f / l for l, f in zip(loop_s, fmu_s)]
    print(f"  master overhead outside FMU calls: median {100 * statistics.median(overhead):.1f} % "
          f"of the stepping loop (range {100 * min(overhead):.1f}-{100 * max(overhead):.1f} %, "
          f"target <= 10 %), {1e6 * statistics.median(own):.2f} µs per macro step; the timers' "
          f"own cost taken out ({1e6 * statistics.median(timers) / steps:.2f} µs per macro "
          f"step); with it left in {100 * statistics.median(raw):.1f} % (range "
          f"{100 * min(raw):.1f}-{100 * max(raw):.1f} %)")


if __name__ == "__main__":
    main()
