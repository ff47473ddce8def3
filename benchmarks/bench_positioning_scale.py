"""Positioning commands at scale: compare, fit (one effect), diagnose and report on 10^7 rows against 60 s and 1.5 GB.

The case: ``--rows`` positioning rows written as a case folder, ``--targets`` targets x
bidirectional runs (lead error, 0.25 µm half-reversal, 0.3 µm noise, targets jittered by
±1 nm), the layout of benchmarks/bench_diagnose_scale.py. Each command runs as the user
runs it (``python -m feedaxis``, reading the case from disk) in its own process: CPU
seconds (user + system, its own and its children's) and peak resident memory (RSS), which
the machine's load inflates far less than wall time; wall time is printed too. ``fit``
writes the model the other commands use.

With ``--baseline-src PATH`` (the ``src`` folder of an earlier commit, e.g. ``git archive
COMMIT src | tar -x -C /tmp/old``) the same commands run from it, interleaved with the
current ones, and each figure is printed as a ratio old / new.

Run: ``python benchmarks/bench_positioning_scale.py [--rows 10000000] [--repeats 1]
[--baseline-src PATH]``.
"""
import argparse
import os
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
sys.path.insert(0, str(HERE))

import synthetic as syn  # noqa: E402
from bench_diagnose_scale import iso_columns  # noqa: E402
from common import arguments, run_command  # noqa: E402
from feedaxis.case import write_case  # noqa: E402

CPU_TARGET_S = 60.0
MEMORY_TARGET_MB = 1500.0


def commands(folder):
    """{name: the command's arguments after ``python -m feedaxis``}, in the order run."""
    case, model = str(folder / "case"), str(folder / "model.toml")
    return {"compare": ["compare", case],
            "fit": ["fit", case, "--add", "lead_error", "--out", model],
            "diagnose": ["diagnose", case, "--model", model],
            "report": ["report", case, "--model", model, "--out", str(folder / "report.html")]}


def run(arguments_, source=None):
    """:class:`common.Command` of ``python -m feedaxis arguments_`` with ``source`` (a
    ``src`` folder) first on the path, else the installed package."""
    environment = dict(os.environ)
    if source:
        environment["PYTHONPATH"] = str(source)
    return run_command([sys.executable, "-m", "feedaxis", *arguments_], env=environment)


def measure(folder, repeats, baseline):
    """{(name, "new" | "old"): [Command]}: every command, the old and new in turn."""
    runs = {}
    for _ in range(repeats):
        for name, arguments_ in commands(folder).items():
            for label, source in (("old", baseline), ("new", None)):
                if label == "old" and not baseline:
                    continue
                runs.setdefault((name, label), []).append(run(arguments_, source))
    return runs


def line(name, label, done):
    cpu = statistics.median(c.cpu_s for c in done)
    peak = max(c.peak_mb for c in done)
    wall = statistics.median(c.wall_s for c in done)
    return (cpu, peak, f"  {name:9s} {label:4s} CPU {cpu:7.1f} s ({cpu / CPU_TARGET_S:4.2f} of "
                       f"{CPU_TARGET_S:.0f} s)  peak RSS {peak:6.0f} MB ({peak / MEMORY_TARGET_MB:4.2f}"
                       f" of {MEMORY_TARGET_MB:.0f} MB)  wall {wall:7.1f} s")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=int, default=10_000_000)
    parser.add_argument("--targets", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=1, help="runs per command (default 1)")
    parser.add_argument("--baseline-src", default=None, metavar="PATH",
                        help="an earlier commit's src folder, run beside for ratios")
    args = arguments(parser, argv, rows=4_000, targets=100, repeats=1)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        write_case(folder / "case", syn.ISO_AXIS,
                   positioning=iso_columns(args.rows, n_targets=args.targets))
        size_mb = (folder / "case" / "positioning.csv").stat().st_size / 1e6
        runs = measure(folder, args.repeats, args.baseline_src)
    print(f"{args.rows:,} positioning rows ({args.targets:,} targets x bidirectional runs, "
          f"positioning.csv {size_mb:.0f} MB); medians of {args.repeats} run(s), peak the "
          "largest")
    for name in commands(Path(".")):
        new_cpu, new_peak, text = line(name, "new", runs[name, "new"])
        print(text)
        if args.baseline_src:
            old_cpu, old_peak, text = line(name, "old", runs[name, "old"])
            print(text)
            print(f"  {name:9s} old / new: CPU {old_cpu / new_cpu:.2f}, peak RSS "
                  f"{old_peak / new_peak:.2f}")


if __name__ == "__main__":
    main()
