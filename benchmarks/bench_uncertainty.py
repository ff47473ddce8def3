"""Uncertainty benchmark (issue 23): the ISO 230-2 figures of 10^5 Monte Carlo trials of a
5 x 5 x 11 test (5 runs each way at 11 targets, 110 readings), and how often the intervals
cover the truth.

Speed, measured side by side in one run, interleaved repeats, medians (min-max):

- vectorised: ``PositioningMeasurement.sample`` over 10^5 trials in chunks (the figures of
  every trial from one ``iso230_figures`` call per chunk, a trials axis);
- per trial: the single-case path, ``iso230_figures`` called once per trial on the same
  trials' deviations (timed on ``--loop-trials`` trials, scaled to 10^5);
- the whole ``feedaxis uncertainty`` evaluation (10^5 trials, each input's share from
  10^4 trials more each), without and with a fitted model (lead_error + backlash: the
  parameters and a 402-point compensation table too).

Coverage (``--cases`` synthetic cases with known truth: lead error, 2 µm backlash, 0.3 µm
Gaussian noise, seeds 1..N): how often the 95 % interval of E, M, B, B̄ (repeatability only,
the budget at 0) holds the figure of the true (noise-free) means.

Run: ``python benchmarks/bench_uncertainty.py [--repeats 5] [--cases 200]``.
"""
import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

import synthetic as syn  # noqa: E402
from feedaxis.case import read_case, write_case  # noqa: E402
from feedaxis.effects import CATALOG  # noqa: E402
from feedaxis.iso230 import iso230_figures  # noqa: E402
from feedaxis.physics import geometry  # noqa: E402
from feedaxis.uncertainty import engine  # noqa: E402
from feedaxis.uncertainty.budget import Budget, CONTRIBUTIONS, default_budget  # noqa: E402
from feedaxis.uncertainty.distributions import Distribution  # noqa: E402
from feedaxis.uncertainty.evaluation import evaluate  # noqa: E402
from feedaxis.uncertainty.positioning import PositioningMeasurement  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments  # noqa: E402

TRIALS = 100_000
NOISE_UM = 0.3
COVERED = ("E_um", "M_um", "B_um", "B_mean_um")


def iso_case(folder, seed):
    """5 runs each way at 11 targets: the case and the true (noise-free) deviations."""
    target_mm, direction, run = syn.iso_layout(n_targets=11, n_runs=5)
    true_um = (geometry.lead_error_um(target_mm, 1.5, 0.012)
               + geometry.backlash_error_um(direction, 2.0))
    error_um = true_um + np.random.default_rng(seed).normal(0.0, NOISE_UM, target_mm.size)
    case = read_case(write_case(folder, syn.ISO_AXIS, positioning={
        "target_mm": target_mm, "error_um": error_um, "direction": direction, "run": run}))
    return case, true_um


def spread(times):
    return f"{statistics.median(times):.3g} s ({min(times):.3g}-{max(times):.3g})"


def speed(folder, repeats, loop_trials, trials):
    case, _ = iso_case(folder / "speed", 1)
    measurement = PositioningMeasurement(case, default_budget())
    chunk = 2 ** 21 // case.positioning.size
    deviations = engine.run(lambda streams, n, active, skip: {
        "x": measurement.trial_deviations(streams, n, active)},
        measurement.inputs, loop_trials, 1, loop_trials)["x"]
    model = CATALOG["lead_error"] + CATALOG["backlash"]
    times = {"vectorised": [], "per trial": [], "evaluate": [], "evaluate + model": []}
    for _ in range(repeats):
        start = time.perf_counter()
        engine.run(measurement.sample, measurement.inputs, trials, 1, chunk)
        times["vectorised"].append(time.perf_counter() - start)
        start = time.perf_counter()
        for values in deviations:
            iso230_figures(case.positioning.target_mm, values, case.positioning.direction)
        times["per trial"].append((time.perf_counter() - start) * trials / loop_trials)
        start = time.perf_counter()
        evaluate(case, trials=trials, seed=1)
        times["evaluate"].append(time.perf_counter() - start)
        start = time.perf_counter()
        evaluate(case, model, trials=trials, seed=1)
        times["evaluate + model"].append(time.perf_counter() - start)
    print(f"figures of {trials} trials of a 5 x 5 x 11 test ({case.positioning.size} readings), "
          f"{repeats} interleaved repeats, medians (min-max):")
    for name, values in times.items():
        print(f"  {name:18s} {spread(values)}")
    ratios = [loop / vector for loop, vector in zip(times["per trial"], times["vectorised"])]
    print(f"  per trial / vectorised: {statistics.median(ratios):.1f}x "
          f"({min(ratios):.1f}-{max(ratios):.1f}), per-trial loop timed on {loop_trials} "
          "trials and scaled")


def coverage(folder, cases):
    zero = Budget({name: Distribution("normal", 0.0) for name in CONTRIBUTIONS},
                  {name: "zero" for name in CONTRIBUTIONS})
    hits = {key: 0 for key in COVERED}
    widths = {key: [] for key in COVERED}
    for seed in range(1, cases + 1):
        case, true_um = iso_case(folder / f"c{seed}", seed)
        truth = iso230_figures(case.positioning.target_mm, true_um, case.positioning.direction)
        result = evaluate(case, budget=zero, trials=10_000, seed=seed)
        for key in COVERED:
            low, high = result.figures[key]["coverage_interval_um"]
            hits[key] += low <= truth[key] <= high
            widths[key].append(high - low)
    print(f"coverage of the 95 % interval over {cases} cases (repeatability only):")
    for key in COVERED:
        rate = hits[key] / cases
        print(f"  {key:10s} {100 * rate:5.1f} % (binomial standard error "
              f"{100 * np.sqrt(rate * (1 - rate) / cases):.1f} %), median width "
              f"{statistics.median(widths[key]):.3f} um")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--loop-trials", type=int, default=5_000)
    parser.add_argument("--cases", type=int, default=200)
    parser.add_argument("--trials", type=int, default=TRIALS,
                        help=f"Monte Carlo trials timed (default {TRIALS})")
    args = arguments(parser, argv, repeats=1, loop_trials=50, cases=2, trials=2_000)
    with threadpool_limits(limits=1, user_api="blas"), tempfile.TemporaryDirectory() as tmp:
        speed(Path(tmp), args.repeats, args.loop_trials, args.trials)
        coverage(Path(tmp), args.cases)


if __name__ == "__main__":
    main()
