"""Tracking commands at scale: compare, fit (servo_plant and Coulomb friction), diagnose and report on 10^7 samples against 70 s and 1.5 GB.

The case: ``--samples`` samples of a servo trace at 1 ms (a 0.1 ms loop, so ten loop steps
a sample), the trace of benchmarks/bench_diagnose_scale.py (Anang et al. 2017's loop on
another plant, white + AR(1) noise) written as a case folder. Each command runs as the user
runs it (``python -m feedaxis``, reading the case from disk) in its own process, as
benchmarks/bench_positioning_scale.py runs the positioning commands (its helpers): CPU
seconds (user + system, its system part beside) and peak resident memory (RSS). ``fit``
(the plant and a Coulomb friction) writes the model the other commands use. 70 s is the
linear reference: the 500 s trace's diagnose took 3.5 s CPU, x 20 at 10^7 samples.

With ``--baseline-src PATH`` (the ``src`` folder of an earlier commit) the same commands
run from it, interleaved, and each figure is printed as a ratio old / new.

Run: ``python benchmarks/bench_tracking_scale.py [--samples 10000000] [--repeats 1]
[--baseline-src PATH]``.
"""
import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_positioning_scale import MEMORY_TARGET_MB, measure, print_runs  # noqa: E402
from common import arguments  # noqa: E402

CPU_TARGET_S = 70.0


def commands(folder):
    """{name: the command's arguments after ``python -m feedaxis``}, in the order run."""
    case, model = str(folder / "case"), str(folder / "model.toml")
    return {"fit": ["fit", case, "--add", "servo_plant", "--add", "coulomb_friction",
                    "--out", model],
            "compare": ["compare", case, "--model", model],
            "diagnose": ["diagnose", case, "--model", model],
            "report": ["report", case, "--model", model, "--out", str(folder / "report.html")]}


def write_trace_folder(folder, samples):
    """Write the trace in a process of its own (a child's peak RSS starts from its
    parent's, so the parent stays small)."""
    code = ("import sys; sys.path[:0] = [sys.argv[1], sys.argv[2]]; "
            "from bench_diagnose_scale import AXIS, tracking_trace; "
            "from feedaxis.case import write_case; "
            "s = tracking_trace(int(sys.argv[4]) * 1e-3).tracking; "
            "write_case(sys.argv[3], {'name': 'trace', 'screw': {'lead_mm': 10.0}, "
            "'servo': dict(AXIS['servo'])}, tracking={'time_s': s.time_s, "
            "'reference_mm': s.reference_mm, 'actual_mm': s.actual_mm})")
    subprocess.run([sys.executable, "-c", code, str(HERE.parent / "tests"), str(HERE),
                    str(folder), str(samples)], check=True)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=10_000_000)
    parser.add_argument("--repeats", type=int, default=1, help="runs per command (default 1)")
    parser.add_argument("--baseline-src", default=None, metavar="PATH",
                        help="an earlier commit's src folder, run beside for ratios")
    args = arguments(parser, argv, samples=5_000, repeats=1)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        write_trace_folder(folder / "case", args.samples)
        size_mb = (folder / "case" / "tracking.csv").stat().st_size / 1e6
        runs = measure(commands(folder), args.repeats, args.baseline_src)
    print(f"{args.samples:,} tracking samples at 1 ms (tracking.csv {size_mb:.0f} MB); "
          f"medians of {args.repeats} run(s), peak the largest")
    print_runs(commands(Path(".")), runs, args.baseline_src, cpu_target_s=CPU_TARGET_S,
               memory_target_mb=MEMORY_TARGET_MB)


if __name__ == "__main__":
    main()
