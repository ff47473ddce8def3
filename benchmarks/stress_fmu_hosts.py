"""Host-safety counts for the issue note: exit-time aborts and memory over cycles.

Run: ``python benchmarks/stress_fmu_hosts.py [--processes 200] [--cycles 1000]``. It builds
the four FMUs, then

- starts ``--processes`` Python processes, each running all four FMUs with
  ``fmpy.simulate_fmu`` in one process and exiting, and counts non-zero exit codes (the
  exit-time heap corruption was rc 134, 4 in 40);
- runs the same number of fmuCheck processes (a C host) on ThermalScrew when
  ``$FEEDAXIS_FMI_TOOLS/fmuCheck.linux64`` exists (docs/fmu-hosts.md);
- instantiates and frees StepperError ``--cycles`` times in this process and prints the
  resident memory growth (after as many warm-up cycles);
- loads StepperError from a freshly unpacked folder ``--cycles`` times (unpack, instantiate,
  initialise, step, free, delete the folder: what ``fmpy.simulate_fmu`` does per call) and
  prints the resident memory growth (it was 0.35 MB a cycle: both libraries stayed mapped).
"""
import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from feedaxis.cosim.fmu_runner import LoadedFmu, run_fmu
from feedaxis.fmu_build import build_fmus

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments  # noqa: E402

FMU_CHECK = Path(os.environ.get("FEEDAXIS_FMI_TOOLS", "fmi-tools")) / "fmuCheck.linux64"
HOST = """
import sys
from fmpy import simulate_fmu
for path in sys.argv[1:]:
    simulate_fmu(path, stop_time=0.05, step_size=0.01)
"""


def resident_kB():
    """Resident set size of this process (kB)."""
    return int(Path("/proc/self/statm").read_text().split()[1]) * 4


def count_failures(commands):
    """Number of commands that exit non-zero; prints each failure's code."""
    failures = 0
    for command in commands:
        run = subprocess.run(command, capture_output=True, text=True)
        if run.returncode != 0:
            failures += 1
            print(f"  rc {run.returncode}: {run.stderr.strip()[-200:]}")
    return failures


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, default=200)
    parser.add_argument("--cycles", type=int, default=1000)
    args = arguments(parser, argv, processes=2, cycles=5)
    with tempfile.TemporaryDirectory() as folder:
        paths = {p.stem: str(p) for p in build_fmus(folder)}
        failed = count_failures([sys.executable, "-c", HOST, *paths.values()]
                                for _ in range(args.processes))
        print(f"fmpy, four FMUs per process: {failed} of {args.processes} processes failed")
        if FMU_CHECK.exists():
            command = [str(FMU_CHECK), "-k", "cs", "-s", "10", "-h", "1", "-l", "3",
                       "-o", str(Path(folder) / "out.csv"), paths["ThermalScrew"]]
            failed = count_failures(command for _ in range(args.processes))
            print(f"fmuCheck, ThermalScrew: {failed} of {args.processes} processes failed")
        loaded = LoadedFmu(paths["StepperError"])
        for _ in range(args.cycles):  # warm-up: the allocator's arenas settle
            loaded.instantiate("cycle").freeInstance()
        before = resident_kB()
        for _ in range(args.cycles):
            loaded.instantiate("cycle").freeInstance()
        print(f"instantiate/free x {args.cycles}: resident memory +{resident_kB() - before} kB")
        loaded.close()
        for _ in range(args.cycles // 10):  # warm-up
            run_fmu(paths["StepperError"], 1e-3, 1)
        before = resident_kB()
        for _ in range(args.cycles):
            run_fmu(paths["StepperError"], 1e-3, 1)
        print(f"load from a fresh folder x {args.cycles}: resident memory "
              f"+{resident_kB() - before} kB")


if __name__ == "__main__":
    sys.exit(main())
