"""Sweeps end to end: a 1-trial sweep in process against the same on a local cluster, and 96 tracking trials on 1 and 2 local workers.

Each figure is the wall time of the whole command in a fresh process (``feedaxis sweep
tracking OUT --vary NpidServo.friction_N=uniform(0,2)``, 10 s of tracking at 1 ms per
trial: imports, the plan, the cluster's start and close, the trials, the outputs), and its
CPU time (the command and every process it started). In one run, interleaved:

- 1 trial with the default workers (run in this process: too small for a cluster) against
  ``--workers 2`` (a local cluster of 2, what the default started before);
- ``--trials 96`` with ``--workers 1`` and with ``--workers 2``: the speed-up of a second
  worker end to end.

The machine's load average is printed with them: on a shared machine the wall times are
only as good as it is idle; the CPU times say what the work itself cost.

The commands run as on an installed feedaxis, whose modules pip compiled once: a
``PYTHONDONTWRITEBYTECODE`` in the environment is dropped for them (with it, every command
would compile feedaxis's hundred modules again, about 0.3 s); the warm-up run writes the
bytecode.

Run: ``python benchmarks/bench_sweep_end_to_end.py [--repeats 3] [--trials 96]``.
"""
import argparse
import os
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import arguments, run_command  # noqa: E402

VARY = "NpidServo.friction_N=uniform(0,2)"


def run_sweep(folder, trials, workers, duration_s):
    """(wall s, CPU s) of one ``feedaxis sweep tracking`` in a fresh process (CPU: the
    command and the worker processes it started and reaped)."""
    out = Path(folder) / f"sweep-{trials}-{workers}"
    shutil.rmtree(out, ignore_errors=True)
    command = [sys.executable, "-m", "feedaxis", "sweep", "tracking", str(out), "--vary", VARY,
               "--trials", str(trials), "--duration-s", str(duration_s)]
    done = run_command(command + ([] if workers is None else ["--workers", str(workers)]))
    return done.wall_s, done.cpu_s


def line(label, runs):
    walls, cpus = [w for w, _ in runs], [c for _, c in runs]
    return (statistics.median(walls), statistics.median(cpus),
            f"{label:<34} wall {statistics.median(walls):6.2f} s ({min(walls):.2f}-"
            f"{max(walls):.2f}), CPU {statistics.median(cpus):6.2f} s ({min(cpus):.2f}-"
            f"{max(cpus):.2f}), {len(runs)} runs")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--trials", type=int, default=96)
    parser.add_argument("--duration-s", type=float, default=10.0)
    args = arguments(parser, argv, repeats=1, trials=4, duration_s=1.2)
    cases = {"1 trial, default (in process)": (1, None), "1 trial, --workers 2": (1, 2),
             f"{args.trials} trials, --workers 1": (args.trials, 1),
             f"{args.trials} trials, --workers 2": (args.trials, 2)}
    runs = {label: [] for label in cases}
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)  # as installed: see the docstring
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as folder:
        run_sweep(folder, 1, 0, args.duration_s)  # FMUs built and cached, numba compiled
        for _ in range(args.repeats):
            for label, (trials, workers) in cases.items():
                runs[label].append(run_sweep(folder, trials, workers, args.duration_s))
    print(f"tracking trials of {args.duration_s:g} s at 1 ms, whole commands; load average "
          f"{load_before:.1f} before, {os.getloadavg()[0]:.1f} after ({os.cpu_count()} cores)")
    figures = {}
    for label, values in runs.items():
        *figures[label], text = line(label, values)
        print(text)
    labels = list(cases)
    here, cluster = figures[labels[0]][0], figures[labels[1]][0]
    one, two = figures[labels[2]][0], figures[labels[3]][0]
    print(f"1 trial: in process / on a local cluster of 2: {here / cluster:.2f} "
          f"({here:.2f} s against {cluster:.2f} s; target <= 1.5 s)")
    print(f"{args.trials} trials: 1 worker / 2 workers: {one / two:.2f}x (target >= 1.6x)")


if __name__ == "__main__":
    main()
