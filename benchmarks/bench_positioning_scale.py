"""Positioning commands at scale: compare, fit (one effect), diagnose and report on 10^7 rows against 60 s and 1.5 GB.

The case: ``--rows`` positioning rows written as a case folder, ``--targets`` targets x
bidirectional runs (lead error, 0.25 µm half-reversal, 0.3 µm noise, targets jittered by
±1 nm), the layout of benchmarks/bench_diagnose_scale.py. Each command runs as the user
runs it (``python -m feedaxis``, reading the case from disk) in its own process: CPU
seconds (user + system, its own and its children's) and peak resident memory (RSS), which
the machine's load inflates far less than wall time; wall time is printed too. ``fit``
writes the model the other commands use. The case is written by a process of its own: the
kernel starts a child's peak RSS from its parent's.

With ``--baseline-src PATH`` (the ``src`` folder of an earlier commit, e.g. ``git archive
COMMIT src | tar -x -C /tmp/old``) the same commands run from it, interleaved with the
current ones, and each figure is printed as a ratio old / new.

What each change bought (issue 35 item 2; peak RSS and CPU seconds of each command on 10^6
rows of this layout, measured one after the other on the loaded 2-core machine):

- the case reader checks a plain CSV in 16 MB chunks and lets NumPy read it from the file,
  never holding its text (the text, its line-end copy and the body slice were three copies):
  reading alone 206 -> 142 MB;
- the outliers' drift by Newton's method over blocks of rows instead of SciPy's soft-L1
  trust region (ten sample-sized arrays), the Jacobian's norms from its Gram matrix and a
  linear model's Jacobian negated in place: fit 428 -> 358 MB;
- few-column least squares through the Gram matrix without a scaled copy
  (``feedaxis.stats.linear``): diagnose 553 -> 458 MB;
- one measurement's deviations held once, not copied by every fit; a basis effect (drift,
  structure) split into its basis unevaluated: fit 358 -> 319 MB, diagnose 458 -> 398 MB;
- glibc's malloc keeps freed blocks up to 1 GB for reuse (the command line's ``mallopt``):
  system time fit 0.82 -> 0.33 s, diagnose 1.50 -> 0.38 s, report 1.11 -> 0.64 s.

Before all of them, on 10^7 rows (the same layout, the machine at load 16): compare 40.7 s
CPU / 1,510 MB, fit 73.9 s / 3,261 MB, diagnose 116.8 s / 4,433 MB, report 183.5 s / 4,619 MB
(system time 9-68 s of it).

Then on 10^7 rows (each command once under ``/usr/bin/time -v``, load 8-12; CPU s / peak
RSS MB), from compare 36.4 / 1,398, fit 57.3 / 2,191, diagnose 73.2 / 3,069, report
121.1 / 3,174 (profiled with memray's high-water mark and cProfile first):

- the fit's split written into one array as each effect is split (an effect whose
  parameters are all linear no longer keeps its columns and a zero base beside the fit's
  copy of them), and kept per value of the nonlinear parameters (a linear model splits
  once per fit, not twice): fit 2,191 -> 1,944 MB, diagnose 3,069 -> 2,611 MB;
- the target clusters (a stable sort of every sample, 1.9 s CPU at 10^7) kept for the
  case's read-only targets instead of sorted again by a dozen figures and fits; fit keeps
  only the RMS before it, not its residual; each effect writes its columns into the fit's
  array: compare 34.1 -> 32.0 s, fit 1,944 -> 1,867 MB, report to 94.1 s / 2,430 MB;
- the run clock of every run at once through one sort by run instead of a pass over the
  samples per run (5,000 passes over 10^7 samples took 28 s): fit 56.3 -> 29.6 s, diagnose
  70.8 -> 43.3 s, report 94.1 -> 68.3 s.

Then (issue 35 items 1-2, bounded memory), from fit 27.3 s CPU / 1,804 MB, compare 29.6 /
1,398, diagnose 42.4 / 2,259, report 68.3 / 2,364 (each once under ``/usr/bin/time``, load
2; memray's high-water mark and a CPU-time cProfile first, at 10^6 and 10^7 rows; every
command's ``--json`` and the report byte-identical at 10^6 before and after):

- the Ljung-Box sums over 65,536 samples at a time, the noise part left in place where the
  samples are already in the order taken, the columns of the case kept as arrays of their
  own (the 4-column table let go), and the diagnosis's refits kept only where the
  measurement's hooks refit (tracking): diagnose's allocations at their peak 2,228 ->
  2,065 MB;
- the eccentricity's, lead error's and backlash's columns written into the fit's array,
  the drift's computed where used (not kept by every model), the projection's residual
  in place, the fit without nuisances let go once the selection moves on: 2,065 -> 1,608
  MB; yet peak RSS stayed at 2.2-2.3 GB: the heap reused sample-sized blocks and the holes
  between them held 0.3-0.5 GB more than the live arrays;
- blocks of 32 MB and more mapped on their own again (``feedaxis.memory``; below that,
  as at 10^6 rows, freed blocks stay for reuse): RSS within 0.1 GB of the allocations,
  at 10 ms of the kernel's per mapped block (diagnose's system time 4 -> 9-13 s);
- the structure search's least squares through a QR taken 65,536 rows at a time
  (``feedaxis.stats.linear.projection``: lstsq held a copy of the cubic's columns and its
  workspace, 380 MB), the fit's residual subtracted a block at a time, sample-sized
  indices in 32 bits where they fit (four of 40 MB each saved), a residual's centring into
  its gathered group means: diagnose 1,658 -> 1,429 MB, report 1,734 -> 1,535 MB;
- the sampling notes' and plausibility check's row groups through a mixed-radix key ranked
  once, a column of few values ranked by searching its sorted values, and the notes
  counting the distinct rows without numbering them: those two 10.5 -> about 5 s CPU,
  report 1,535 -> 1,458 MB.

Side by side with the old code (below, one run each at load 8-10): peak RSS old / new
1.29 (compare), 1.46 (fit), 1.68 (diagnose), 1.62 (report), every command under 1.5 GB.
Not met: CPU. The mapped blocks cost the kernel 10 ms each (system time 3-5 -> 8-16 s a
command), more than the user time saved (report 63 -> 52 s user): old / new CPU 0.88-0.89
for fit, diagnose and report, report 74 s against 60 (the old 66 s). What remains at the
peak of diagnose and report, 70 and 40 MB under 1.5 GB: the fit of 7 columns (534 MB: lead
error, drift, backlash, eccentricity) beside the case's columns, its indices and three
residuals; a fit that evaluates its columns a block of rows at a time would take it, and
with it most of the mapped blocks. The refusal's cost of a row (``feedaxis.case``) is
measured from these runs.

Then (issue 35 item 2, the report's CPU), from report 77.5 s CPU (60.8 user, 16.8
system) / 1,493 MB (one run under ``/usr/bin/time``, load 2-4; cProfile in CPU time at
10^7 rows, memray's high-water mark, getrusage's user and system time; every command's
``--json``, the model and the report byte-identical at 10^6 before and after):

- the sampling notes' count of rows repeating a target, direction and run through an
  in-place sort of their keys (NumPy 2.4's unique hashed the 10^7 distinct keys for 14 s
  of the 77), the target groups searched among their 2,000 keys (two unique's sorts,
  3.0 s): report 60.8 -> 48.8 s user;
- a column of whole numbers from 0 to fewer than its size (a dense key: the rows' keys, a
  run, a target index) ranked, and its distinct values counted, through the keys present
  (the plausibility check's row groups: a sort of 10^7 keys, 1.7 s); whether the targets
  vary or both directions occur from their extremes and signs (NumPy's unique hashed 10^7
  targets, 2 s over 16 calls);
- glibc's heap trimmed before each candidate fit of the diagnosis: diagnose's peak
  1,463 -> 1,444 MB (one run each).

Side by side with the old code (below, one run each at load 4.5-6): report 71.9 -> 57.8 s
CPU (old / new 1.24), compare 1.61, fit 1.24, diagnose 1.07; peak RSS unchanged or lower,
every command under 60 s and 1.5 GB; report's margins 2 s and 42 MB. Tried and left:
pyarrow's CSV reader (a dependency already) read the same table bit for bit (the fuzz
corpus and near-valid tables as the per-cell reader did) in 2.3 s CPU where NumPy's takes
9.4 (report 46.7 s CPU), but its library and pool took the peak 38 MB higher (report
1,523-1,528 MB, diagnose 1,482): over 1.5 GB. Every sample-sized block still mapped on its
own (``feedaxis.memory``; with none mapped, system time 3.5 s but 2.0 GB resident): the
kernel's time (diagnose 10-14 s, report 17-22 s) is now the largest share left, the fit
of 7 columns (560 MB) the largest block at the peak; the ISO figures' 16 sorts by target
take 1.8 s and ``direction`` in 8 bits would save 70 MB (60 uses): neither worth the
memory or the risk.

Run: ``python benchmarks/bench_positioning_scale.py [--rows 10000000] [--repeats 1]
[--baseline-src PATH]``.
"""
import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from common import arguments, run_command  # noqa: E402

CPU_TARGET_S = 60.0
MEMORY_TARGET_MB = 1500.0


def commands(folder):
    """{name: the command's arguments after ``python -m feedaxis``}, in the order run."""
    case, model = str(folder / "case"), str(folder / "model.toml")
    return {"compare": ["compare", case],
            "fit": ["fit", case, "--add", "lead_error", "--out", model],
            "diagnose": ["diagnose", case, "--model", model],
            "report": ["report", case, "--model", model, "--out", str(folder / "report.html")]}


def write_case_folder(folder, rows, targets):
    """Write the case in a process of its own: a child's peak RSS as the kernel reports it
    starts from its parent's (exec keeps the high-water mark), so the parent stays small."""
    code = ("import sys; sys.path[:0] = [sys.argv[1], sys.argv[2]]; import synthetic as syn; "
            "from bench_diagnose_scale import iso_columns; from feedaxis.case import write_case; "
            "write_case(sys.argv[3], syn.ISO_AXIS, positioning=iso_columns(int(sys.argv[4]), "
            "n_targets=int(sys.argv[5])))")
    subprocess.run([sys.executable, "-c", code, str(HERE.parent / "tests"), str(HERE),
                    str(folder), str(rows), str(targets)], check=True)


def run(arguments_, source=None):
    """:class:`common.Command` of ``python -m feedaxis arguments_`` with ``source`` (a
    ``src`` folder) first on the path, else the installed package."""
    environment = dict(os.environ)
    if source:
        environment["PYTHONPATH"] = str(source)
    return run_command([sys.executable, "-m", "feedaxis", *arguments_], env=environment)


def measure(commands_, repeats, baseline):
    """{(name, "new" | "old"): [Command]}: every command of ``commands_`` ({name: its
    arguments}, run in their order), the old and new in turn."""
    runs = {}
    for _ in range(repeats):
        for name, arguments_ in commands_.items():
            for label, source in (("old", baseline), ("new", None)):
                if label == "old" and not baseline:
                    continue
                runs.setdefault((name, label), []).append(run(arguments_, source))
    return runs


def line(name, label, done, cpu_target_s=CPU_TARGET_S, memory_target_mb=MEMORY_TARGET_MB):
    """(median CPU s, largest peak RSS MB, the line printing them against the targets)."""
    cpu = statistics.median(c.cpu_s for c in done)
    system = statistics.median(c.system_s for c in done)
    peak = max(c.peak_mb for c in done)
    wall = statistics.median(c.wall_s for c in done)
    return (cpu, peak, f"  {name:9s} {label:4s} CPU {cpu:7.1f} s ({cpu / cpu_target_s:4.2f} of "
                       f"{cpu_target_s:.0f} s; system {system:5.1f} s)  peak RSS {peak:6.0f} MB "
                       f"({peak / memory_target_mb:4.2f} of {memory_target_mb:.0f} MB)  wall "
                       f"{wall:7.1f} s")


def print_runs(names, runs, baseline, **targets):
    """Each command's line (old beside new with ``baseline``, and their ratios)."""
    for name in names:
        new_cpu, new_peak, text = line(name, "new", runs[name, "new"], **targets)
        print(text)
        if baseline:
            old_cpu, old_peak, text = line(name, "old", runs[name, "old"], **targets)
            print(text)
            print(f"  {name:9s} old / new: CPU {old_cpu / new_cpu:.2f}, peak RSS "
                  f"{old_peak / new_peak:.2f}")


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
        write_case_folder(folder / "case", args.rows, args.targets)
        size_mb = (folder / "case" / "positioning.csv").stat().st_size / 1e6
        runs = measure(commands(folder), args.repeats, args.baseline_src)
    print(f"{args.rows:,} positioning rows ({args.targets:,} targets x bidirectional runs, "
          f"positioning.csv {size_mb:.0f} MB); medians of {args.repeats} run(s), peak the "
          "largest")
    print_runs(commands(Path(".")), runs, args.baseline_src)


if __name__ == "__main__":
    main()
