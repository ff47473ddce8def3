"""Standalone FMUs against the FMUs that use this machine's Python: size, start-up, stepping.

Run: ``python benchmarks/bench_standalone.py [--repeats 9] [--steps 2000] [--instructions]``.
It builds both
sets of the four FMUs, compiles ``tests/fmi_c_host.c`` with ``tests/fmi2_c_host.c`` (a C host:
no Python in the process until an FMU starts one) and, per FMU and repeat, runs it in a fresh
process on the unpacked FMU, the two builds interleaved (standalone, not, standalone, ...). Each run reports the
first ``fmi2Instantiate`` (the standalone FMU starts the Python it carries, the other the
build machine's) and the µs per step (set the inputs, ``fmi2DoStep``, get the outputs) on
the axis schedule (1 ms; the thermal screw 0.1 s, a tenth as many). It prints medians with
quartiles, and each standalone FMU's size by part (unpacked / compressed MB).
``--instructions`` counts instead, once per FMU and build, the instructions executed
(valgrind's callgrind: about the same count whatever else the machine does): by the host
process to the end of initialisation (a run with no step), and inside fmi2SetReal,
fmi2DoStep and fmi2GetReal per step (a run of ``--steps // 4`` steps).
"""
import argparse
import re
import statistics
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from fmpy import read_model_description  # noqa: E402

from common import arguments  # noqa: E402
from feedaxis.fmu_build import AXIS_FMU_NAMES, build_fmus  # noqa: E402
from feedaxis.fmu_standalone import runtime_sizes  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
STEP_S = {"NpidServo": 1e-3, "StepperError": 1e-3, "GeometricError": 1e-3, "ThermalScrew": 0.1}
INPUT_VALUES = {"position_ref_mm": 5.0, "disturbance_N": 0.0, "position_mm": 5.0,
                "velocity_mm_s": 50.0, "ambient_C": 20.0}


def compile_host(folder):
    program = Path(folder) / "fmi_c_host"
    subprocess.run(["cc", "-O2", f"-I{ROOT / 'fmus' / 'common' / 'fmi2'}", "-o", str(program),
                    str(ROOT / "tests" / "fmi_c_host.c"), str(ROOT / "tests" / "fmi2_c_host.c"),
                    "-ldl"], check=True)
    return program


def host_command(program, fmu_path, unpacked, n_steps):
    """The C host's command line for one FMU (inputs set each step, every output read)."""
    with zipfile.ZipFile(fmu_path) as archive:
        archive.extractall(unpacked)
    description = read_model_description(str(fmu_path))
    name = description.coSimulation.modelIdentifier
    variables = description.modelVariables
    inputs = ",".join(f"{v.valueReference}={INPUT_VALUES[v.name]}" for v in variables
                      if v.causality == "input")
    outputs = ",".join(str(v.valueReference) for v in variables if v.causality == "output")
    steps = n_steps // 10 if name == "ThermalScrew" else n_steps  # 0.1 s steps: fewer
    return [str(program), str(unpacked), name, description.guid, repr(STEP_S[name]), str(steps),
            "1", inputs, outputs]


def measure(command):
    """(first fmi2Instantiate s, µs per step) of one fresh host process."""
    run = subprocess.run(command, capture_output=True, text=True)
    if run.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed:\n{run.stdout[-3000:]}{run.stderr}")
    values = dict(line.split()[:2] for line in run.stdout.splitlines()
                  if line.startswith(("instantiate_s", "step_us")))
    return float(values["instantiate_s"]), float(values["step_us"])


STEP_FUNCTIONS = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal")


def instructions(command, inside=()):
    """Instructions executed by the host process (``inside``: only within these functions,
    callees included), counted by callgrind."""
    toggles = [f"--toggle-collect={function}" for function in inside]
    run = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                          *toggles, *command], capture_output=True, text=True)
    if run.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed under valgrind:\n{run.stderr[-3000:]}")
    return int(re.search(r"Collected : (\d+)", run.stderr).group(1))


def print_instructions(commands, n_steps):
    """Instructions to the end of initialisation and per step, per FMU and build."""
    print(f"\ninstructions (callgrind), millions: to the end of initialisation, per step "
          f"(from {n_steps} steps)")
    counted = {}
    for (kind, name), command in commands.items():
        steps = int(command[5])
        started = instructions(command[:5] + ["0"] + command[6:])
        stepping = instructions(command, STEP_FUNCTIONS)
        counted[(kind, name)] = (started / 1e6, stepping / steps / 1e6)
    for name in AXIS_FMU_NAMES:
        alone, plain = counted[("standalone", name)], counted[("not standalone", name)]
        print(f"{name:<16}standalone {alone[0]:8.1f} {alone[1]:8.4f}   not standalone "
              f"{plain[0]:8.1f} {plain[1]:8.4f}   per-step ratio {alone[1] / plain[1]:.3f}")


def summary(values, scale=1.0, digits=3):
    low, middle, high = statistics.quantiles([v * scale for v in values], n=4)
    return f"{statistics.median(values) * scale:.{digits}f} ({low:.{digits}f}-{high:.{digits}f})"


def print_sizes(standalone):
    print("\nstandalone FMU sizes, MB unpacked / compressed (the .fmu file)")
    for name, path in standalone.items():
        parts = sorted(runtime_sizes(path).items(), key=lambda item: -item[1][1])
        print(f"{name}: {path.stat().st_size / 1e6:.1f} MB; "
              + ", ".join(f"{part} {unpacked / 1e6:.1f}/{packed / 1e6:.1f}"
                          for part, (unpacked, packed) in parts))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9, help="interleaved repeats (default 9)")
    parser.add_argument("--instructions", action="store_true",
                        help="count instructions with callgrind instead of timing")
    parser.add_argument("--steps", type=int, default=2000,
                        help="steps per run (the thermal screw's 0.1 s steps: a tenth; "
                             "default 2000)")
    args = arguments(parser, argv, repeats=2, steps=40)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        sets = {"standalone": build_fmus(folder / "standalone", AXIS_FMU_NAMES,
                                         standalone=True),
                "not standalone": build_fmus(folder / "plain", AXIS_FMU_NAMES)}
        program = compile_host(folder)
        n_steps = args.steps // 4 if args.instructions else args.steps
        commands = {(kind, path.stem): host_command(program, path, folder / kind / path.stem,
                                                    n_steps)
                    for kind, paths in sets.items() for path in paths}
        if args.instructions:
            print_instructions(commands, n_steps)
            return
        runs = {key: [] for key in commands}
        for _ in range(args.repeats):
            for key, command in commands.items():
                runs[key].append(measure(command))
        print(f"C host, fresh process per run: median (quartiles) of {args.repeats} "
              "interleaved runs")
        print(f"{'FMU':<16}{'build':<16}{'first instantiate ms':>24}{'µs per step':>24}")
        for name in AXIS_FMU_NAMES:
            for kind in sets:
                starts, steps = zip(*runs[(kind, name)])
                print(f"{name:<16}{kind:<16}{summary(starts, 1e3, 0):>24}"
                      f"{summary(steps, 1, 1):>24}")
            ratios = [s[1] / n[1] for s, n in zip(runs[("standalone", name)],
                                                  runs[("not standalone", name)])]
            print(f"{'':<16}{'step ratio':<16}{'':>24}{summary(ratios, 1, 2):>24}")
        print_sizes({path.stem: path for path in sets["standalone"]})


if __name__ == "__main__":
    sys.exit(main())
