"""Diagnose benchmark (issue 4): wall time on the 2,501-point demo case and on a 3-hour
thermal case, and where the time goes.

Run: ``python benchmarks/bench_diagnose.py [--repeats 5]``. Wall times are medians of
interleaved repeats in this one run; the breakdown is a cProfile of one more run, as a
share of that run's total.
"""
import argparse
import cProfile
import pstats
import statistics
import sys
import tempfile
import time
from pathlib import Path

from feedaxis.case import read_case
from feedaxis.diagnose import diagnose
from feedaxis.effects import CATALOG, Model
from feedaxis.examples import BUNDLED_CASE, write_table2_case
from feedaxis.fit import fit

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments  # noqa: E402

# where the time goes: function name (file suffix, function) -> label
STAGES = {
    ("thermal.py", "duty_unit_fields"): "thermal field (duty_unit_fields)",
    ("_lsq/least_squares.py", "least_squares"): "least-squares fits (all, incl. model evaluations)",
    ("feedaxis/diagnose.py", "find_structures"): "unexplained-structure search",
    ("stats/spectrum.py", "amplitude_spectrum"): "residual spectrum",
    ("_numdiff.py", "approx_derivative"): "finite-difference Jacobians",
}


def cases(folder):
    """{label: (case, starting model)}: the demo case after lead error; thermal after lead."""
    thermal_case = read_case(write_table2_case(Path(folder) / "thermal", 6000.0, seed=1))
    demo_case = read_case(BUNDLED_CASE)
    lead = Model([CATALOG["lead_error"]])
    return {"2,501-point demo case (model: lead_error)": (demo_case, fit(lead, demo_case).model),
            "3-hour thermal case, 308 samples (model: lead_error)":
                (thermal_case, fit(lead, thermal_case).model)}


def breakdown(case, model):
    profile = cProfile.Profile()
    profile.enable()
    diagnose(case, model)
    profile.disable()
    stats = pstats.Stats(profile).stats
    total = max(ct for (_, _, _), (_, _, _, ct, _) in stats.items())
    shares = {}
    for (path, _, name), (_, calls, _, cumulative, _) in stats.items():
        for (suffix, function), label in STAGES.items():
            if path.endswith(suffix) and name == function:
                shares[f"{label}, {calls} calls"] = cumulative / total
    return shares


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = arguments(parser, argv, repeats=1)
    with tempfile.TemporaryDirectory() as folder:
        subjects = cases(folder)
        times = {label: [] for label in subjects}
        for _ in range(args.repeats):
            for label, (case, model) in subjects.items():
                start = time.perf_counter()
                diagnose(case, model)
                times[label].append(time.perf_counter() - start)
        for label, (case, model) in subjects.items():
            verdict = diagnose(case, model)
            print(f"{label}: diagnose median {statistics.median(times[label]):.3f} s "
                  f"(min {min(times[label]):.3f}, max {max(times[label]):.3f}, "
                  f"{args.repeats} repeats); verdict {verdict.verdict}, candidates "
                  f"{[c.effect for c in verdict.candidates]}")
            for stage, share in sorted(breakdown(case, model).items(), key=lambda kv: -kv[1]):
                print(f"    {100 * share:5.1f} %  {stage}")


if __name__ == "__main__":
    main()
