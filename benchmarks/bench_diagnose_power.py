"""Diagnosis decision benchmark (issue 10): false-alarm rate on generated nulls of both
layouts and the power to name a backlash against a plain paired t-test.

Nulls (the model is the truth, lead error): ISO 230-2 repeats (21 targets x 5 bidirectional
runs, 0.3 µm noise, a drift of 0.05 µm per run, 2 spikes of ±3 µm) and dense single-pass
scans (501 samples, 0.3 µm noise, a 1 µm drift over the pass, 2 spikes). A false alarm is
any effect or structure named other than the drift, or an outlier missed or invented.

Power: ISO 230-2 cases with a backlash B (0.3 µm noise, 105 pairs); the share of trials in
which ``diagnose`` names backlash first, against the share in which a plain paired t-test of
x(+) - x(-) gives p < 0.001. The smallest B named with 95 % power is interpolated on the grid.

Run: ``python benchmarks/bench_diagnose_power.py [--trials 200]``.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

import synthetic as syn  # noqa: E402
from feedaxis.diagnose import diagnose  # noqa: E402
from feedaxis.stats.judge import FAMILY_ALPHA  # noqa: E402
from feedaxis.effects import CATALOG, Model  # noqa: E402

LEAD = Model([CATALOG["lead_error"]])
BACKLASH_GRID_UM = np.round(np.arange(0.05, 0.351, 0.025), 3)


def false_alarm_rate(layout, trials, seed):
    rng = np.random.default_rng(seed)
    alarms = 0
    for _ in range(trials):
        case, spikes = syn.NULL_LAYOUTS[layout](rng)
        alarms += syn.false_alarm(diagnose(case, LEAD), spikes)
    return alarms / trials


def smallest_with_power(grid, power, target=0.95):
    """Linear interpolation of the first crossing of ``target``; NaN when never reached."""
    above = np.flatnonzero(np.asarray(power) >= target)
    if above.size == 0:
        return float("nan")
    i = above[0]
    if i == 0:
        return float(grid[0])
    return float(np.interp(target, [power[i - 1], power[i]], [grid[i - 1], grid[i]]))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=200, help="trials per null layout and "
                        "per backlash (default 200)")
    args = parser.parse_args()
    start = time.perf_counter()
    print(f"family-wise error rate of a whole diagnosis: {FAMILY_ALPHA:g}")
    for seed, layout in enumerate(syn.NULL_LAYOUTS):
        rate = false_alarm_rate(layout, args.trials, seed)
        print(f"nulls, {layout}: false alarms {rate * args.trials:.0f} of {args.trials} "
              f"({100 * rate:.1f} %)")
    print(f"{'B (µm)':>8s} {'diagnose':>10s} {'paired t':>10s}")
    named, t_test = [], []
    for i, backlash_um in enumerate(BACKLASH_GRID_UM):
        power = syn.backlash_power(diagnose, LEAD, backlash_um, args.trials, seed=100 + i)
        named.append(power[0])
        t_test.append(power[1])
        print(f"{backlash_um:8.3f} {power[0]:10.3f} {power[1]:10.3f}")
    b_diagnose = smallest_with_power(BACKLASH_GRID_UM, named)
    b_t_test = smallest_with_power(BACKLASH_GRID_UM, t_test)
    print(f"smallest B with 95 % power: diagnose {b_diagnose:.3f} µm, paired t-test "
          f"{b_t_test:.3f} µm, ratio {b_diagnose / b_t_test:.2f} (target <= 1.3)")
    print(f"({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
