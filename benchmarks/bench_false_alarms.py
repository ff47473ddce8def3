"""False alarms of the one diagnosis, for every kind of measurement, under one policy.

The family-wise error rate of a whole diagnosis under the complete null is 0.001 for every
kind (``feedaxis.stats.judge``: split over the measurement's stages, Bonferroni over the
terms tried). This benchmark measures it: null cases whose model is the truth, diagnosed;
a false alarm is any effect or structure named (a positioning null's drift and spikes are
its nuisances: reported as such they are not alarms, see ``tests/synthetic.py``).

Families: positioning, the two layouts of ``tests/synthetic.NULL_LAYOUTS`` (ISO 230-2
repeats with a drift and two spikes; a dense single-pass scan with a drift and two spikes);
tracking, 2 s records at 1 ms of the plant of ``tests/test_tracking_loop.py`` with white
0.1 µm + AR(1) 0.3 µm noise, model ``servo_plant``.

Run: ``python benchmarks/bench_false_alarms.py [--trials 200]``; prints each family's rate
with its 95 % Clopper-Pearson interval.
"""
import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

import synthetic as syn  # noqa: E402
from feedaxis.case import read_case  # noqa: E402
from feedaxis.diagnose import diagnose  # noqa: E402
from feedaxis.effects import CATALOG, Model  # noqa: E402
from feedaxis.stats.judge import FAMILY_ALPHA  # noqa: E402
from tracking_synthetic import step_loop, two_sines, write_tracking_case  # noqa: E402

LEAD = Model([CATALOG["lead_error"]])
PLANT = {"plant_gain_mm_per_Vs2": 70000.0, "plant_damping_per_s": 150.0,
         "plant_stiffness_per_s2": 250.0, "delay_s": 0.0015}


def positioning_family(layout):
    def alarms(trials, seed, folder):
        rng = np.random.default_rng(seed)
        return sum(syn.false_alarm(diagnose(case, LEAD), spikes)
                   for case, spikes in (syn.NULL_LAYOUTS[layout](rng) for _ in range(trials)))
    return alarms


def tracking_family(trials, seed, folder):
    run = step_loop(two_sines, 2.0, plant=PLANT)
    model = Model([CATALOG["servo_plant"]], {"servo_plant": PLANT})
    return sum(diagnose(read_case(write_tracking_case(Path(folder) / f"n{k}", run,
                                                      seed * 100_000 + k)),
                        model).verdict != "adequate" for k in range(trials))


FAMILIES = {**{f"positioning, {layout}": positioning_family(layout)
               for layout in syn.NULL_LAYOUTS},
            "tracking, 2 s at 1 ms, white + AR(1) noise": tracking_family}


def clopper_pearson(alarms, trials, level=0.95):
    """Two-sided interval of a binomial rate."""
    tail = (1 - level) / 2
    low = stats.beta.ppf(tail, alarms, trials - alarms + 1) if alarms else 0.0
    high = stats.beta.ppf(1 - tail, alarms + 1, trials - alarms) if alarms < trials else 1.0
    return low, high


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=200, help="nulls per family (default 200)")
    args = parser.parse_args(argv)
    print(f"family-wise error rate of a whole diagnosis, every kind: {FAMILY_ALPHA:g}")
    with tempfile.TemporaryDirectory() as folder:
        for seed, (name, family) in enumerate(FAMILIES.items()):
            started = time.perf_counter()
            alarms = family(args.trials, seed, folder)
            low, high = clopper_pearson(alarms, args.trials)
            print(f"{name}: {alarms} false alarms in {args.trials} nulls "
                  f"({100 * alarms / args.trials:.2f} %, 95 % interval {100 * low:.2f}-"
                  f"{100 * high:.2f} %; {time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
