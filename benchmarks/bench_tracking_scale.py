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

Issue 35 on tracking, profiled first (memray's high-water mark, a CPU-time cProfile,
getrusage's user and system time; 10^6 and 2·10^6 samples, then 10^7 once); every change
leaves fit, diagnose and compare ``--json`` byte-identical (10^5 and 2·10^5 samples, the
model fitted and the empty one). Before, on 10^7 samples (each command once under
``/usr/bin/time``, load 3-5; CPU s user + system / peak RSS MB): diagnose 217.2 + 100.4 /
21,555 (the second change below in place; from the empty model it had not finished in 15
minutes), compare 13.1 + 3.5 / 1,366.

- The reference's near-stops were kept apart from its reversals through a near-stops x
  reversals matrix, quadratic in the record's length (about 10^9 cells on this trace at
  10^7 samples: 16 GB, the 100 s in the kernel); the nearest reversal from its two
  neighbours in sorted order gives the same gap to the bit: diagnose on 10^7 samples
  317.6 -> 267.4 s CPU, 21,555 -> 5,857 MB.
- The fit's Jacobian negates its columns and sensitivities in the one array it returns
  (it made a negated copy of each); the variable projection's subtracts and negates in
  place; a sensitivity pass too large for the loop's cache (128 MB: from about 3·10^6
  samples on) is scaled to µm in place; the screening's design negates the Jacobian into
  itself; the plain fit's Jacobian, never read again, is let go before the fit with the
  nuisances: two to three samples x parameters arrays less at a fit's peak (diagnose on
  10^6 samples: 938 -> 900 MB resident).

After, on 10^7 samples (the same way, load 5-8): compare 14.4 + 2.4 s / 1,366 MB, fit
234.9 + 58.7 / 5,856, diagnose 190.5 + 76.9 / 5,857, report 454.6 + 144.3 / 5,857 (on
10^6 samples report took 43.6 + 3.4 s: its user time grew 10.4 times for 10 times the
samples, its system time 42 times). The run on 10^6 samples below is one of each under
load; diagnose there twice more, alternating (CPU s, peak RSS): old 22.2 and 22.1 s, 961 MB;
new 21.6 and 22.2 s, 922 MB.

Not met, and why: 1.5 GB. The peak of fit, diagnose and report is the first fit's trust
region (the plant's 4 parameters, the friction's 1 and the drift's 2: 7 columns). SciPy's
``least_squares`` (``trf``, exact) holds the Jacobian twice (its own and the copy it hands
out), the augmented Jacobian and its SVD's U, four samples x 7 arrays (224 bytes a
sample), while the fit builds the next Jacobian (56 bytes) from a sensitivity pass (40):
with the record's columns about 600 bytes a sample. 1.5 GB at 10^7 samples is 135; a
solver on the Gram matrix or on a QR taken in blocks would reach it, but its steps, so the
fitted values, would not be the same to the bit. Nor 70 s: the loop takes ten steps a
sample (10^8 a pass at 10^7) and a fit makes 10-30 passes, each about 1 s (the
sensitivity pass) or 0.2 s (a simulation) a 10^6 samples, so the CPU time grows with the
samples (fit 26 s at 10^6, 294 s at 10^7), and the system time with it: every array above
32 MB is mapped fresh (``feedaxis.memory``), the trust region's four per iteration too.

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
