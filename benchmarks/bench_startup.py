"""Start-up of the tracking commands (issue 21): how long ``feedaxis fit``, ``compare`` and
``diagnose`` on a tracking case take before their work starts.

Each command runs as its own process, as a user runs it, on a 5 s tracking record (the plant of
Anang et al. 2017, PID, tests/tracking_synthetic.py). A wrapper ends the process as soon as the
first servo simulation (``feedaxis.physics.servo.simulate``, the numba-compiled loop)
returns: the time from spawning the process to then is the start-up (Python, the imports,
reading the case, numba and its compiled loop). The same wrapper can end the process just
before that first simulation instead ("before JIT"): the start-up without numba.

Conditions, interleaved in one run:

- warm: numba's cache folder (``NUMBA_CACHE_DIR``) holds the compiled loop from an earlier
  run, as it does for every run after the first wherever numba can cache
  (``feedaxis.physics.numba_cache``);
- cold: an empty cache folder for every run: the loop is compiled anew, what each run paid
  where nothing persisted (numba refusing to cache on a read-only install without a
  writable user cache before ``numba_cache``).

Run: ``python benchmarks/bench_startup.py [--repeats 7]``. Medians (and min-max) of the
repeats; ratios cold / warm side by side.
"""
import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from common import arguments  # noqa: E402

from tracking_synthetic import step_loop, two_sines, write_tracking_case  # noqa: E402

# Runs the CLI; ends the process right after (or, with STOP_BEFORE set, right before) the
# first servo simulation.
WRAPPER = """
import os, sys
from feedaxis.physics import servo
original = servo.simulate
def first_simulation(*args, **kwargs):
    if os.environ.get("STOP_BEFORE"):
        os._exit(0)
    original(*args, **kwargs)
    os._exit(0)
servo.simulate = first_simulation
import feedaxis.measurement.tracking as tracking
tracking.simulate = first_simulation
from feedaxis.cli import main
sys.exit(main(sys.argv[1:]))
"""


def make_case(folder):
    """A 5 s tracking record and a model fitted to it; (case, model file)."""
    case = write_tracking_case(folder / "case", step_loop(two_sines, 5.0), seed=1)
    model = folder / "model.toml"
    subprocess.run([sys.executable, "-m", "feedaxis.cli", "fit", str(case), "--add",
                    "servo_plant", "--out", str(model)], check=True, capture_output=True)
    return case, model


def start_up_s(argv, cache_dir, stop_before=False):
    """(wall, CPU) seconds from spawning ``feedaxis ARGV`` to the end of its first servo
    simulation; CPU = user + system time of the process (what the load of a shared
    machine does not inflate)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    if stop_before:
        env["STOP_BEFORE"] = "1"
    cpu_before = _children_cpu_s()
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", WRAPPER, *argv], env=env,
                          capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{argv}: exit {done.returncode}\n{done.stderr[-2000:]}")
    return elapsed, _children_cpu_s() - cpu_before


def _children_cpu_s():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def summary(values):
    return f"{statistics.median(values):5.2f} s ({min(values):.2f}-{max(values):.2f})"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = arguments(parser, argv, repeats=1)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        case, model = make_case(folder)
        commands = {"fit": ["fit", str(case), "--add", "servo_plant"],
                    "compare": ["compare", str(case), "--model", str(model)],
                    "diagnose": ["diagnose", str(case), "--model", str(model)]}
        warm_dir = folder / "warm-cache"
        start_up_s(commands["compare"], warm_dir)           # compiles once into it
        times = {(name, condition): [] for name in commands
                 for condition in ("warm", "cold", "before JIT")}
        for repeat in range(args.repeats):
            for name, argv in commands.items():
                times[name, "warm"].append(start_up_s(argv, warm_dir))
                times[name, "cold"].append(start_up_s(argv, folder / f"cold-{name}-{repeat}"))
                times[name, "before JIT"].append(start_up_s(argv, warm_dir, stop_before=True))
    print(f"start-up of tracking commands, median (min-max) of {args.repeats} interleaved "
          f"runs; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for which, label in ((0, "wall clock"), (1, "CPU time (user + system)")):
        print(f"\n{label}")
        print(f"{'command':10s} {'warm cache':>20s} {'cold (compiles)':>20s} "
              f"{'before JIT':>20s} {'cold/warm':>10s}")
        for name in commands:
            warm, cold, before = ([pair[which] for pair in times[name, c]]
                                  for c in ("warm", "cold", "before JIT"))
            print(f"{name:10s} {summary(warm):>20s} {summary(cold):>20s} "
                  f"{summary(before):>20s} "
                  f"{statistics.median(cold) / statistics.median(warm):9.1f}x")

if __name__ == "__main__":
    main()
