"""Co-simulation benchmark: the full axis, 10 s tracking at a 1 ms macro step.

Run: ``python benchmarks/bench_cosim.py [--repeats 5] [--stop-s 10]``. In one run, with
repeats interleaved, it times

- the project's master (feedaxis.cosim.master) running the four FMUs, end to end
  (extract, instantiate, 10 000 macro steps recording every output, free), with its
  compiled macro-step loop (feedaxis.cosim.compiled_loop, the default) and with its Python
  loop (the fallback where no C compiler exists), in alternating order: the stepping loop's
  wall time and the whole run's CPU time (this process: the FMUs run in it), the ratio
  compiled / Python taken within each repeat (the machine is shared: a busy moment slows
  the repeat it falls on);
- OSP libcosim (libcosimpy) running the exported .ssp end to end (load, instantiate, the
  same 10 000 steps with the reference set by an override manipulator and the same outputs
  observed every step) -- the driver of tests/libcosim_driver.py;
- the master with every FMU call timed, in each loop: the share of its stepping loop spent
  outside the FMUs' own fmi2SetReal/fmi2DoStep/fmi2GetReal calls (the master's own share).
  The timers cost time outside the calls they time (the Python loop: a Python call and two
  clock reads each, about as much as the master's own work per call; the compiled loop:
  two clock reads): the master calibrates that cost per timed call in the same process
  (``Timing.timer_s``) and takes it out of the loop; the share with the timers left in is
  printed too (an upper bound);
- a cross-check without timers: each loop stepping null FMUs (the same four instances, whose
  fmi2SetReal, fmi2DoStep and fmi2GetReal are replaced by compiled C functions that do
  nothing and return fmi2OK: the same plan, copies, ratio tests and recorded rows). Its
  stepping loop over the real one's, per repeat, is an upper bound of the master's own
  share (it includes the calls themselves: for the Python loop, fmpy's ctypes calls,
  which the timed share counts as the FMUs').

It prints medians (and ranges) and the ratios: of the medians, or the median of the
per-repeat ratios where said.
"""
import argparse
import ctypes
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from feedaxis.cosim.fmu_runner import LoadedFmu
from feedaxis.cosim.master import Master
from feedaxis.cosim.ssp import export_ssp
from feedaxis.cosim.system import default_axis
from feedaxis.fmu_build import build_fmus
from feedaxis.toolchain import c_compiler

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


def time_master(system, fmu_paths, stop_s, profile=False, compiled=True):
    """(end-to-end wall seconds, end-to-end CPU seconds of this process, Timing of the run)."""
    reference = reference_mm(int(round(stop_s / system.macro_step_s)), system.macro_step_s)
    started, cpu_started = time.perf_counter(), time.process_time()
    with Master(system, fmu_paths, compiled_loop=compiled) as master:
        result = master.run(stop_s, {"position_ref_mm": reference}, profile=profile)
    elapsed, cpu_s = time.perf_counter() - started, time.process_time() - cpu_started
    assert np.isfinite(result["table_position_mm"]).all()
    assert master.timing.loop == "compiled" or not compiled, master.timing.loop
    return elapsed, cpu_s, master.timing


NULL_FMU = """
int null_values(void *c, const unsigned *vr, unsigned long n, double *values) { return 0; }
int null_step(void *c, double t, double h, int no_prior) { return 0; }
"""


def null_functions(folder):
    """(FMI 3.0?, set, step, get): compiled functions that do nothing and return fmi2OK, in
    the signatures of fmi2SetReal, fmi2DoStep and fmi2GetReal."""
    source, library = Path(folder) / "null_fmu.c", Path(folder) / "null_fmu.so"
    source.write_text(NULL_FMU, encoding="utf-8")
    subprocess.run([c_compiler(), "-shared", "-fPIC", "-O2", "-o", str(library), str(source)],
                   check=True)
    loaded = ctypes.CDLL(str(library))
    values, step = loaded.null_values, loaded.null_step
    values.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p]
    step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    return False, values, step, values


def null_loop_s(system, fmu_paths, stop_s, compiled, nulls):
    """The stepping loop's wall seconds with every FMU's stepping calls replaced by ``nulls``
    (instantiation and initialisation are the FMUs' own)."""
    native = LoadedFmu.native_stepping_functions
    LoadedFmu.native_stepping_functions = lambda self, slave: nulls
    try:
        return time_master(system, fmu_paths, stop_s, compiled=compiled)[2].loop_s
    finally:
        LoadedFmu.native_stepping_functions = native


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


def share_line(label, profiled, steps):
    """The master's own share of the stepping loop over the profiled runs of one loop."""
    share = [t.overhead_fraction for t in profiled]
    own = [(t.loop_s - t.timer_s - t.fmu_s) / steps for t in profiled]
    raw = [1 - t.fmu_s / t.loop_s for t in profiled]
    return (f"  {label}: median {100 * statistics.median(share):.1f} % of the stepping loop "
            f"(range {100 * min(share):.1f}-{100 * max(share):.1f} %), "
            f"{1e6 * statistics.median(own):.2f} µs per macro step; the timers' own cost taken "
            f"out ({1e6 * statistics.median([t.timer_s for t in profiled]) / steps:.2f} µs "
            f"per macro step); with it left in {100 * statistics.median(raw):.1f} % (range "
            f"{100 * min(raw):.1f}-{100 * max(raw):.1f} %)")


def ratio_line(label, compiled, python, unit="s"):
    """Medians of both loops and the median (range) of the per-repeat ratios."""
    ratios = [c / p for c, p in zip(compiled, python)]
    return (f"  {label}: compiled {describe(compiled, unit)}; Python {describe(python, unit)}; "
            f"compiled / Python per repeat median {statistics.median(ratios):.3f} (range "
            f"{min(ratios):.3f}-{max(ratios):.3f})")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--stop-s", type=float, default=10.0)
    args = arguments(parser, argv, repeats=1, stop_s=0.05)
    system = default_axis()
    runs = {(compiled, profile): [] for compiled in (True, False) for profile in (False, True)}
    libcosim_s, engine_s, null_s = [], [], {True: [], False: []}
    with tempfile.TemporaryDirectory() as folder:
        fmu_paths = {p.stem: p for p in build_fmus(Path(folder) / "fmus")}
        ssp_path = export_ssp(Path(folder) / "axis.ssp", system, fmu_paths)
        nulls = null_functions(folder)
        for compiled in (True, False):  # warm-up: first imports inside the FMUs, the library
            time_master(system, fmu_paths, 1.0, compiled=compiled)
        for repeat in range(args.repeats):
            for profile in (False, True):
                for compiled in (True, False)[::1 if repeat % 2 else -1]:
                    runs[compiled, profile].append(
                        time_master(system, fmu_paths, args.stop_s, profile, compiled))
            for compiled in (True, False):
                null_s[compiled].append(null_loop_s(system, fmu_paths, args.stop_s, compiled,
                                                    nulls))
            libcosim_s.append(time_libcosim(ssp_path, system, args.stop_s))
            engine_s.append(time_libcosim_engine(ssp_path, args.stop_s))
    steps = int(round(args.stop_s / system.macro_step_s))
    master_s = [wall for wall, _, _ in runs[True, False]]
    print(f"full axis, {args.stop_s:g} s tracking (20 mm, 0.7 Hz), macro step "
          f"{system.macro_step_s * 1e3:g} ms = {steps} macro steps, thermal every "
          f"{system.ratio(system.component('ThermalScrew'))}; {args.repeats} interleaved repeats")
    print(f"  project master, end to end : {describe(master_s)}")
    print(f"  libcosim on the .ssp       : {describe(libcosim_s)}")
    ratio = statistics.median(master_s) / statistics.median(libcosim_s)
    print(f"  master / libcosim wall time: {ratio:.2f} (target <= 1)")
    print(f"  libcosim engine alone      : {describe(engine_s)}; master / engine "
          f"{statistics.median(master_s) / statistics.median(engine_s):.2f}")
    plain = {compiled: runs[compiled, False] for compiled in (True, False)}
    print(ratio_line("stepping loop, wall time   ", *([t.loop_s for _, _, t in plain[c]]
                                                      for c in (True, False))))
    print(ratio_line("run (instantiate to free)  ", *([t.wall_s for _, _, t in plain[c]]
                                                      for c in (True, False))))
    print(ratio_line("end to end, CPU time       ", *([cpu for _, cpu, _ in plain[c]]
                                                      for c in (True, False))))
    setup = [t.wall_s - t.loop_s for _, _, t in runs[True, True]]
    print(f"  setup (instantiate + initialise, compiled loop, profiled runs): {describe(setup)}")
    print("  the master's own share of its stepping loop, outside the FMU calls "
          "(target <= 10 %):")
    for compiled, label in ((True, "compiled loop"), (False, "Python loop  ")):
        print(share_line(label, [t for _, _, t in runs[compiled, True]], steps))
    print("  cross-check without timers: the stepping loop over null FMUs / over the FMUs, "
          "per repeat (an upper bound of the master's own share):")
    for compiled, label in ((True, "compiled loop"), (False, "Python loop  ")):
        bound = [n / t.loop_s for n, (_, _, t) in zip(null_s[compiled], plain[compiled])]
        print(f"  {label}: median {100 * statistics.median(bound):.1f} % (range "
              f"{100 * min(bound):.1f}-{100 * max(bound):.1f} %), null FMUs "
              f"{1e6 * statistics.median(null_s[compiled]) / steps:.2f} µs per macro step")


if __name__ == "__main__":
    main()
