"""The FMUs' cost against the FMI floor: the full axis per 1 ms macro step vs empty FMUs.

Run: ``python benchmarks/bench_fmi_floor.py [--repeats 7] [--steps 2000]``. It builds the
four feedaxis FMUs and four empty pythonfmu FMUs with the same interface (the same
variables, names, types and causalities; ``do_step`` does nothing), and drives both sets
with the same raw fmpy ctypes calls (``fmi2SetReal`` of the inputs, ``fmi2DoStep``,
``fmi2GetReal`` of the outputs; preallocated arrays, as feedaxis.cosim.master does) on the
default axis schedule: servo, motor and geometric error every 1 ms macro step, the thermal
screw every 0.1 s. Repeats are interleaved (full, empty, full, ...). It prints the median
cost per macro step of each set and per FMU (so the servo's share can be read on its own),
the ratio of the medians, and the spread of the ratio over the interleaved pairs (the
machine is shared: a busy moment slows the pair it falls on).
"""
import argparse
import ctypes
import statistics
import sys
import tempfile
import time
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from feedaxis.fmu_build import FMU_NAMES, build_fmus

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments  # noqa: E402

MACRO_STEP_S = 1e-3
EVERY = {"NpidServo": 1, "StepperError": 1, "GeometricError": 1, "ThermalScrew": 100}
INPUT_VALUES = {"position_ref_mm": 5.0, "disturbance_N": 0.0, "position_mm": 5.0,
                "velocity_mm_s": 50.0, "ambient_C": 20.0}
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


class Driven:
    """One instantiated, initialised FMU with preallocated input/output arrays."""

    def __init__(self, path):
        description = read_model_description(str(path))
        self.slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(str(path)),
                               modelIdentifier=description.coSimulation.modelIdentifier,
                               instanceName="bench")
        self.slave.instantiate()
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
        set_real(component, self.in_vrs, len(self.in_vrs), self.in_values)
        do_step(component, time_s, step_s, 1)
        get_real(component, self.out_vrs, len(self.out_vrs), self.out_values)

    def free(self):
        self.slave.terminate()
        self.slave.freeInstance()


def time_per_macro_step_us(paths, n_steps):
    """{name: µs per macro step spent in that FMU's calls} for one run of ``n_steps``."""
    driven = {name: Driven(paths[name]) for name in FMU_NAMES}
    spent = dict.fromkeys(FMU_NAMES, 0.0)
    try:
        for k in range(n_steps):
            for name in FMU_NAMES:
                every = EVERY[name]
                if (k + 1) % every == 0:
                    started = time.perf_counter()
                    driven[name].step((k + 1 - every) * MACRO_STEP_S, every * MACRO_STEP_S)
                    spent[name] += time.perf_counter() - started
    finally:
        for fmu in driven.values():
            fmu.free()
    return {name: 1e6 * seconds / n_steps for name, seconds in spent.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15,
                        help="interleaved repeats (default 15)")
    parser.add_argument("--steps", type=int, default=2000, help="macro steps per run (default 2000)")
    args = arguments(parser, argv, repeats=2, steps=200)
    with tempfile.TemporaryDirectory() as folder:
        full = {p.stem: p for p in build_fmus(Path(folder) / "full")}
        empty = build_empty_fmus(full, Path(folder))
        runs = {"full": [], "empty": []}
        for _ in range(args.repeats):
            for kind, paths in (("full", full), ("empty", empty)):
                runs[kind].append(time_per_macro_step_us(paths, args.steps))
    medians = {kind: {name: statistics.median(r[name] for r in results) for name in FMU_NAMES}
               for kind, results in runs.items()}
    totals = {kind: statistics.median(sum(r.values()) for r in results)
              for kind, results in runs.items()}
    print(f"µs per 1 ms macro step (median of {args.repeats} interleaved runs of "
          f"{args.steps} steps; thermal every 100 steps)")
    print(f"{'FMU':<16}{'feedaxis':>10}{'empty':>10}{'ratio':>8}")
    for name in FMU_NAMES:
        ratio = medians["full"][name] / medians["empty"][name]
        print(f"{name:<16}{medians['full'][name]:>10.1f}{medians['empty'][name]:>10.1f}"
              f"{ratio:>8.2f}")
    without_servo = {kind: totals[kind] - medians[kind]["NpidServo"] for kind in totals}
    print(f"{'full axis':<16}{totals['full']:>10.1f}{totals['empty']:>10.1f}"
          f"{totals['full'] / totals['empty']:>8.2f}")
    print(f"{'axis w/o servo':<16}{without_servo['full']:>10.1f}{without_servo['empty']:>10.1f}"
          f"{without_servo['full'] / without_servo['empty']:>8.2f}")
    pair_ratios = sorted(sum(f.values()) / sum(e.values())
                         for f, e in zip(runs["full"], runs["empty"]))
    low, _, high = statistics.quantiles(pair_ratios, n=4)
    print(f"full axis ratio over the {len(pair_ratios)} interleaved pairs: median "
          f"{statistics.median(pair_ratios):.2f}, quartiles {low:.2f}-{high:.2f}, "
          f"range {pair_ratios[0]:.2f}-{pair_ratios[-1]:.2f}")


if __name__ == "__main__":
    sys.exit(main())
