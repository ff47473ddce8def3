"""The FMUs' cost against the FMI floor: per FMU and for the axis, in each controller mode.

Run: ``python benchmarks/bench_fmi_floor.py [--repeats 15] [--steps 2000] [--starts 5]
[--instructions] [--standalone] [--fmus DIR] [--smoke]``. It builds the four feedaxis FMUs
(or takes them from ``--fmus``) and two sets of FMUs with the same interface (the same
variables, names, types, causalities and value references) and no physics:

- **native**: minimal C FMUs (``benchmarks/native_fmu.c`` compiled against the official
  FMI 2.0 headers, ``fmus/common/fmi2/``): the floor any FMU pays in this host;
- **empty pythonfmu**: pythonfmu slaves whose ``do_step`` does nothing.

All are driven by the same raw fmpy ctypes calls (``fmi2SetReal`` of the inputs,
``fmi2DoStep``, ``fmi2GetReal`` of the outputs; preallocated arrays, as
feedaxis.cosim.master does) on the default axis schedule: servo, motor and geometric error
every 1 ms macro step, the thermal screw every 0.1 s. The feedaxis set runs in each
controller mode of the servo (PID; NPID, Anang et al. 2017 Eq. 8; PID with Coulomb friction). Each
FMU is driven alone on its schedule and the four together (the axis); the cost is the CPU
time of this process per macro step (a busy machine delays the process, which wall time
would count). One repeat runs every set once, in an order rotated from repeat to repeat; a
ratio is taken within each repeat (the machine is shared: a busy moment slows the repeat it
falls on, also in CPU time, through the caches), and the table gives the median of the
per-repeat ratios with their quartiles.

``--instructions`` also counts the instructions per macro step of the axis under valgrind's
callgrind (two runs of each set, the difference per step: start-up cancels), a figure the
machine's load does not move; valgrind must be installed. It takes minutes per set.

``--starts`` times the first instantiate + initialisation of each freshly extracted FMU in
fresh processes, after the first import (numpy, fmpy and pythonfmu imported, one other FMU
loaded: what every FMU but the first in a process pays).

``--standalone`` adds the standalone build (``feedaxis build-fmus --standalone``: each FMU
carrying its Python; in this Python host it runs on the host's interpreter) to the
interleaved sets, in the PID mode, and prints its cost and per-repeat ratio to the feedaxis
FMUs.

**What the feedaxis FMUs pay per step.** The four FMUs step without entering Python: their
host layer calls each FMU's step compiled ahead of time by numba
(``feedaxis.physics.fmu_steps``, the same physics functions the slaves' Python steps call, in
the FMU's compiled module ``physics/step_kernel``; fmus/README.md) on a block of numbers the
slave packs after any call that may change it, and answers fmi2SetReal and fmi2GetReal of
the inputs and outputs in C. What is left above the floor is the physics itself (the servo's
10 loop steps of 0.1 ms per 1 ms step, the geometric error's sines and table look-up, the
thermal screw's 80 cells every hundredth macro step) and the host layer's checks of each
call. Before the compiled steps each of the three that step every macro step entered Python
once per step (the slave's exchange function, 1-2 µs per FMU): the full axis cost 1.88, 1.91
and 1.91 times the floor in PID, NPID and friction mode (the same command with
``--repeats 9`` on main at e914964, 2026-11-26 21:33 UTC, load average 1.0-2.0). With those
three compiled and ThermalScrew still in Python (main at 397ea5b) it cost 1.17, 1.19 and 1.20
times the floor on a quiet machine (load 0.6). ThermalScrew's Python step, 33 µs of CPU a
doStep through fmpy, takes 4.1 µs compiled (the driver's calls included); counted with
callgrind inside the host layer's doStep, 246,000 instructions became 17,200: per macro step
of the axis 2,460 and 172, 3.3 and 0.23 % of the native floor's 72,000-82,000, so the axis
gains about 3 % of the floor. The same command with ``--repeats 9``, once for the
build before (397ea5b) and once for this one, one after the other at load average 4-5 on the
shared machine: the full axis 1.27, 1.39 and 1.28 times the floor before, 1.15, 1.14 and 1.13
after (quartiles up to 2.11 before and 1.58 after). ``--instructions`` (callgrind over the
whole axis) cannot resolve that gain: its start-up differs from run to run by millions of
instructions, so the native floor itself counted 72,300 to 82,400 per macro step in four runs
(``--steps 1000`` and ``2000``, before and after); it gave 1.03-1.18 with the compiled thermal
step and 1.04-1.34 before it.
"""
import argparse
import ast
import ctypes
import itertools
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from feedaxis.fmu_build import AXIS_FMU_NAMES, build_fmus
from feedaxis.toolchain import c_compiler

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments  # noqa: E402
from plain_pythonfmu import free_instance  # noqa: E402

MACRO_STEP_S = 1e-3
EVERY = {"NpidServo": 1, "StepperError": 1, "GeometricError": 1, "ThermalScrew": 100}
INPUT_VALUES = {"position_ref_mm": 5.0, "disturbance_N": 0.0, "position_mm": 5.0,
                "velocity_mm_s": 50.0, "ambient_C": 20.0}
# the servo's parameters in each controller mode (20 N of Coulomb friction: 0.2 V at the
# default 100 N/V, a fifth of the command a 0.25 mm error gives at kp = 0.9 V/mm)
MODES = {"PID": {}, "NPID": {"nonlinear": True}, "friction": {"friction_N": 20.0}}
NATIVE_SOURCE = Path(__file__).resolve().parent / "native_fmu.c"
FMI_HEADERS = Path(__file__).resolve().parents[1] / "fmus" / "common" / "fmi2"
EMPTY_SLAVE = '''from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer
from pythonfmu import Real, String

TYPES = {{"Real": (Real, 0.0), "Integer": (Integer, 1), "Boolean": (Boolean, False),
         "String": (String, "")}}
VARIABLES = {variables!r}


class {name}(Fmi2Slave):
    """Same interface as the feedaxis FMU, no physics."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        for name, kind, causality in VARIABLES:
            variable_type, value = TYPES[kind]
            setattr(self, name, value)
            options = {{"causality": getattr(Fmi2Causality, causality)}}
            if causality == "parameter":
                options["variability"] = Fmi2Variability.fixed
            self.register_variable(variable_type(name, **options))

    def do_step(self, current_time, step_size):
        return True
'''
FIRST_START = '''
import sys, time
import numpy, pythonfmu  # the first import
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
sys.path.insert(0, sys.argv[4])
from plain_pythonfmu import free_instance

def start(path, parameters):
    description = read_model_description(path)
    slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(path),
                      modelIdentifier=description.coSimulation.modelIdentifier,
                      instanceName="start")
    variables = {v.name: v for v in description.modelVariables}
    started = time.perf_counter(), time.process_time()
    slave.instantiate()
    for name, value in parameters.items():
        setter = slave.setBoolean if isinstance(value, bool) else slave.setReal
        setter([variables[name].valueReference], [value])
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave, (time.perf_counter() - started[0], time.process_time() - started[1])

other, _ = start(sys.argv[1], {})
slave, times = start(sys.argv[2], eval(sys.argv[3]))
print(*times)
for started_slave in (slave, other):
    started_slave.terminate()
    free_instance(started_slave)
'''


def build_empty_fmus(fmu_paths, out_dir):
    """{name: path} of pythonfmu FMUs declaring the same variables as ``fmu_paths``."""
    from pythonfmu.builder import FmuBuilder
    empty = {}
    for name, path in fmu_paths.items():
        variables = [(v.name, v.type, v.causality)
                     for v in read_model_description(str(path)).modelVariables]
        script = Path(out_dir) / f"Empty{name}.py"
        script.write_text(EMPTY_SLAVE.format(name=f"Empty{name}", variables=variables))
        empty[name] = Path(FmuBuilder.build_FMU(script, dest=out_dir))
    return empty


def build_native_fmus(fmu_paths, out_dir):
    """{name: path} of C FMUs with the model description of ``fmu_paths`` (native_fmu.c)."""
    compiler = c_compiler()
    if compiler is None:
        raise SystemExit("the native floor needs a C compiler (cc or gcc, or set CC)")
    native = {}
    for name, path in fmu_paths.items():
        description = read_model_description(str(path))
        identifier = description.coSimulation.modelIdentifier
        n_values = 1 + max(v.valueReference for v in description.modelVariables)
        library = Path(out_dir) / f"native_{identifier}.so"
        subprocess.run([compiler, "-shared", "-fPIC", "-O2", "-Wall", f"-I{FMI_HEADERS}",
                        f"-DN_VALUES={n_values}", "-o", str(library), str(NATIVE_SOURCE)],
                       check=True)
        native[name] = Path(out_dir) / f"Native{name}.fmu"
        with zipfile.ZipFile(path) as source, zipfile.ZipFile(native[name], "w") as fmu:
            fmu.writestr("modelDescription.xml", source.read("modelDescription.xml"))
            fmu.write(library, f"binaries/linux64/{identifier}.so")
    return native


class Driven:
    """One instantiated, initialised FMU with preallocated input/output arrays."""

    def __init__(self, path, parameters):
        description = read_model_description(str(path))
        self.unzip_dir = extract(str(path))
        self.slave = FMU2Slave(guid=description.guid, unzipDirectory=self.unzip_dir,
                               modelIdentifier=description.coSimulation.modelIdentifier,
                               instanceName="bench")
        self.slave.instantiate()
        variables = {v.name: v for v in description.modelVariables}
        for name, value in parameters.items():
            setter = self.slave.setBoolean if isinstance(value, bool) else self.slave.setReal
            setter([variables[name].valueReference], [value])
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()
        inputs = [v for v in description.modelVariables if v.causality == "input"]
        outputs = [v for v in description.modelVariables if v.causality == "output"]
        self.in_vrs = (ctypes.c_uint * len(inputs))(*[v.valueReference for v in inputs])
        self.in_values = (ctypes.c_double * len(inputs))(*[INPUT_VALUES[v.name] for v in inputs])
        self.out_vrs = (ctypes.c_uint * len(outputs))(*[v.valueReference for v in outputs])
        self.out_values = (ctypes.c_double * len(outputs))()
        self.calls = [self.slave._functions[f] for f in ("fmi2SetReal", "fmi2DoStep",
                                                         "fmi2GetReal")]

    def step(self, time_s, step_s):
        set_real, do_step, get_real = self.calls
        component = self.slave.component
        if (set_real(component, self.in_vrs, len(self.in_vrs), self.in_values)
                or do_step(component, time_s, step_s, 1)
                or get_real(component, self.out_vrs, len(self.out_vrs), self.out_values)):
            raise RuntimeError("an FMU call failed during the benchmark")

    def free(self):
        self.slave.terminate()
        free_instance(self.slave)
        shutil.rmtree(self.unzip_dir, ignore_errors=True)



def cpu_us_per_macro_step(paths, names, n_steps, servo_parameters):
    """CPU µs of this process per macro step driving the FMUs ``names`` for ``n_steps``."""
    driven = [(Driven(paths[name], servo_parameters if name == "NpidServo" else {}), EVERY[name])
              for name in names]
    try:
        started = time.process_time()
        for k in range(1, n_steps + 1):
            for fmu, every in driven:
                if k % every == 0:
                    fmu.step((k - every) * MACRO_STEP_S, every * MACRO_STEP_S)
        spent = time.process_time() - started
    finally:
        for fmu, _ in driven:
            fmu.free()
    return 1e6 * spent / n_steps


def one_repeat(paths, n_steps, servo_parameters):
    """{FMU name: CPU µs per macro step} of each FMU driven alone, and ``"axis"``: all four
    driven together."""
    run = {name: cpu_us_per_macro_step(paths, [name], n_steps, servo_parameters)
           for name in AXIS_FMU_NAMES}
    run["axis"] = cpu_us_per_macro_step(paths, AXIS_FMU_NAMES, n_steps, servo_parameters)
    return run


def interleaved_runs(sets, repeats, n_steps):
    """{set name: [{FMU name: µs per macro step}, ...]}, one run per set and repeat, the
    order of the sets rotated from repeat to repeat."""
    names = list(sets)
    runs = {name: [] for name in names}
    for repeat in range(repeats):
        for name in names[repeat % len(names):] + names[:repeat % len(names)]:
            paths, servo_parameters = sets[name]
            runs[name].append(one_repeat(paths, n_steps, servo_parameters))
    return runs


def spread(values):
    """'median (q1-q3)' of ``values`` (the quartiles are the extremes below four values)."""
    values = sorted(values)
    low, high = (statistics.quantiles(values, n=4)[::2] if len(values) >= 4
                 else (values[0], values[-1]))
    return f"{statistics.median(values):.2f} ({low:.2f}-{high:.2f})"


def print_floor_tables(runs, repeats, n_steps):
    """Per mode: µs per macro step of each FMU and the axis, and the per-repeat ratios."""
    print(f"CPU µs per 1 ms macro step, median of {repeats} interleaved repeats of {n_steps} "
          f"steps (thermal every 100 steps); ratios: median of the per-repeat ratios "
          f"(quartiles)")
    for mode in MODES:
        print(f"\n{mode}: {'FMU':<16}{'native':>8}{'empty':>8}{'feedaxis':>10}"
              f"{'feedaxis/native':>22}{'feedaxis/empty':>22}")
        for row in (*AXIS_FMU_NAMES, "axis"):
            cost = {kind: statistics.median(run[row] for run in runs[kind])
                    for kind in ("native", "empty", mode)}
            over_native = spread(f[row] / n[row] for f, n in zip(runs[mode], runs["native"]))
            over_empty = spread(f[row] / e[row] for f, e in zip(runs[mode], runs["empty"]))
            label = "full axis" if row == "axis" else row
            print(f"{'':<{len(mode) + 2}}{label:<16}{cost['native']:>8.1f}{cost['empty']:>8.1f}"
                  f"{cost[mode]:>10.1f}{over_native:>22}{over_empty:>22}")
    servo = [run["NpidServo"] for run in runs["PID"]]
    for mode in ("NPID", "friction"):
        ratios = (run["NpidServo"] / pid for run, pid in zip(runs[mode], servo))
        print(f"NpidServo {mode} / PID: {spread(ratios)}")


def print_standalone(runs):
    """The standalone FMUs against the feedaxis FMUs in the PID mode (same physics, same
    host): CPU µs per macro step and the per-repeat ratio."""
    print(f"\nstandalone: {'FMU':<16}{'µs':>8}{'standalone/feedaxis':>26}")
    for row in (*AXIS_FMU_NAMES, "axis"):
        cost = statistics.median(run[row] for run in runs["standalone"])
        ratio = spread(a[row] / f[row] for a, f in zip(runs["standalone"], runs["PID"]))
        label = "full axis" if row == "axis" else row
        print(f"{'':<12}{label:<16}{cost:>8.1f}{ratio:>26}")


def first_start_ms(fmu_paths, other, starts):
    """{label: [(wall ms, CPU ms), ...]} of the first instantiate + initialisation of each
    FMU (and the servo in NPID) in ``starts`` fresh processes each, after ``other`` was
    loaded."""
    cases = [(name, fmu_paths[name], {}) for name in AXIS_FMU_NAMES]
    cases.append(("NpidServo NPID", fmu_paths["NpidServo"], MODES["NPID"]))
    times = {label: [] for label, _, _ in cases}
    for _, (label, path, parameters) in itertools.product(range(starts), cases):
        run = subprocess.run([sys.executable, "-c", FIRST_START, str(other), str(path),
                              repr(parameters), str(Path(__file__).resolve().parent)],
                             capture_output=True, text=True, check=True)
        times[label].append(tuple(1e3 * float(s) for s in run.stdout.split()[-2:]))
    return times


def instructions_per_macro_step(paths, servo_parameters, n_steps):
    """Instructions per macro step of the axis: callgrind's total for ``n_steps`` and for
    ``n_steps // 5`` steps, the difference per step (hash seed fixed: the runs repeat)."""
    totals = []
    for steps in (n_steps // 5, n_steps):
        run = subprocess.run(
            ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", sys.executable,
             __file__, "--drive", repr(({k: str(v) for k, v in paths.items()},
                                        servo_parameters, steps))],
            capture_output=True, text=True, check=True, env={**os.environ, "PYTHONHASHSEED": "0"})
        totals.append(int(run.stderr.split("Collected : ")[1].split()[0]))
    return (totals[1] - totals[0]) / (n_steps - n_steps // 5)


def print_instruction_table(sets, n_steps):
    """Instructions per macro step of the axis for every set, and the feedaxis ratios."""
    counts = {name: instructions_per_macro_step(paths, parameters, n_steps)
              for name, (paths, parameters) in sets.items()}
    print(f"\ninstructions per 1 ms macro step of the axis (callgrind, {n_steps} steps "
          f"less {n_steps // 5})")
    print(f"  native {counts['native']:,.0f}, empty pythonfmu {counts['empty']:,.0f}")
    for mode in MODES:
        print(f"  {mode:<9}{counts[mode]:>10,.0f}  feedaxis/native "
              f"{counts[mode] / counts['native']:.2f}  feedaxis/empty "
              f"{counts[mode] / counts['empty']:.2f}")
    if "standalone" in counts:
        print(f"  {'standalone':<9}{counts['standalone']:>10,.0f}  standalone/feedaxis (PID) "
              f"{counts['standalone'] / counts['PID']:.2f}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15,
                        help="interleaved repeats (default 15)")
    parser.add_argument("--steps", type=int, default=2000, help="macro steps per run (default 2000)")
    parser.add_argument("--starts", type=int, default=5,
                        help="fresh processes per FMU for the first-start times (default 5)")
    parser.add_argument("--fmus", type=Path, help="take the feedaxis FMUs from this folder")
    parser.add_argument("--instructions", action="store_true",
                        help="also count instructions per macro step under callgrind")
    parser.add_argument("--standalone", action="store_true",
                        help="also time the standalone FMUs (feedaxis build-fmus --standalone)")
    parser.add_argument("--drive", help=argparse.SUPPRESS)  # one axis run, for callgrind
    # smoke: two repeats (the ratios' spread), 200 steps (the thermal screw steps twice), one
    # fresh process per first start; --instructions stays opt-in (valgrind, minutes per set)
    args = arguments(parser, argv, repeats=2, steps=200, starts=1)
    if args.drive:
        paths, servo_parameters, n_steps = ast.literal_eval(args.drive)
        cpu_us_per_macro_step({k: Path(v) for k, v in paths.items()}, AXIS_FMU_NAMES,
                              n_steps, servo_parameters)
        return 0
    with tempfile.TemporaryDirectory() as folder:
        full = ({name: args.fmus / f"{name}.fmu" for name in AXIS_FMU_NAMES} if args.fmus else
                {p.stem: p for p in build_fmus(Path(folder) / "full", AXIS_FMU_NAMES)})
        sets = {"native": (build_native_fmus(full, folder), {}),
                "empty": (build_empty_fmus(full, folder), {})}
        sets.update({mode: (full, parameters) for mode, parameters in MODES.items()})
        if args.standalone:
            sets["standalone"] = ({p.stem: p for p in build_fmus(
                Path(folder) / "standalone", AXIS_FMU_NAMES, standalone=True)}, MODES["PID"])
        runs = interleaved_runs(sets, args.repeats, args.steps)
        print_floor_tables(runs, args.repeats, args.steps)
        if "standalone" in runs:
            print_standalone(runs)
        if args.instructions:
            print_instruction_table(sets, args.steps)
        if args.starts:
            empty_stepper = sets["empty"][0]["StepperError"]
            times = first_start_ms(full, empty_stepper, args.starts)
            print(f"\nfirst instantiate + initialisation, ms (median and range of "
                  f"{args.starts} fresh processes, after the first import): wall, CPU")
            for label, values in times.items():
                wall, cpu = ([v[i] for v in values] for i in (0, 1))
                print(f"  {label:<16}{statistics.median(wall):>8.1f} ({min(wall):.1f}-"
                      f"{max(wall):.1f}){statistics.median(cpu):>8.1f} ({min(cpu):.1f}-"
                      f"{max(cpu):.1f})")


if __name__ == "__main__":
    sys.exit(main())
