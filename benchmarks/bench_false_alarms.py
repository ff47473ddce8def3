"""False alarms of the one diagnosis, for every kind of measurement, under one policy.

The family-wise error rate of a whole diagnosis under the complete null is 0.001 for every
kind (``feedaxis.stats.judge``: split over the measurement's stages, Bonferroni over the
terms tried). This benchmark measures it: null cases whose model is the truth, diagnosed;
a false alarm is any effect or structure named (a positioning null's drift and spikes are
its nuisances: reported as such they are not alarms, see ``tests/synthetic.py``).

Families: positioning, the two layouts of ``tests/synthetic.NULL_LAYOUTS`` (ISO 230-2
repeats with a drift and two spikes; a dense single-pass scan with a drift and two spikes);
tracking, 2 s records at 1 ms of the plant of ``tests/test_tracking_loop.py``, model
``servo_plant`` at the truth, with encoder noise (white 0.1 µm + AR(1) 0.3 µm) and each
null family of ``tests/tracking_synthetic.NOISE_FAMILIES`` (white; AR(1) with ρ = 0.5 and
0.95; Student-t with ν = 3; quantised to 0.1 µm; a slow drift, the tracking diagnosis's
nuisance; three single-sample spikes, its outliers: neither is an alarm when reported as
such). A tracking line also gives the share of nulls with outliers left out and, for the
spikes, the share where exactly the three spikes were found.

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
from feedaxis.measurement import Tracking  # noqa: E402
from feedaxis.stats.judge import FAMILY_ALPHA  # noqa: E402
from tracking_synthetic import (NOISE_FAMILIES, spike_indices, step_loop,  # noqa: E402
                                two_sines, write_tracking_case)

LEAD = Model([CATALOG["lead_error"]])
PLANT = {"plant_gain_mm_per_Vs2": 70000.0, "plant_damping_per_s": 150.0,
         "plant_stiffness_per_s2": 250.0, "delay_s": 0.0015}


def positioning_family(layout):
    def alarms(trials, seed, folder):
        rng = np.random.default_rng(seed)
        return sum(syn.false_alarm(diagnose(case, LEAD), spikes)
                   for case, spikes in (syn.NULL_LAYOUTS[layout](rng) for _ in range(trials)))
    return alarms


def tracking_false_alarm(diagnosis):
    """True when a tracking null diagnosis names an effect or a structure (a drift is its
    nuisance, spikes its outliers)."""
    return bool(diagnosis.candidates) or any(s.kind != "drift" for s in diagnosis.unexplained)


def tracking_family(family):
    """Nulls of one noise family (None: the encoder noise); prints the outliers' shares."""
    def alarms(trials, seed, folder):
        run = step_loop(two_sines, 2.0, plant=PLANT)
        model = Model([CATALOG["servo_plant"]], {"servo_plant": PLANT})
        count = with_outliers = spikes_found = 0
        for k in range(trials):
            noise_seed = seed * 100_000 + k
            case = read_case(write_tracking_case(Path(folder) / f"t{seed}-{k}", run, noise_seed,
                                                 family=family))
            found = diagnose(case, model)
            count += tracking_false_alarm(found)
            with_outliers += bool(found.outlier_rows)
            if family == "spikes":
                spikes = spike_indices(run[0].size, noise_seed)
                compared = spikes[np.isin(spikes, Tracking(case).index)]
                spikes_found += found.outlier_rows == (compared + 2).tolist()
        extra = f"; exactly the spikes found in {spikes_found}" if family == "spikes" else ""
        print(f"  (outliers left out in {with_outliers} of {trials}{extra})")
        return count
    return alarms


FAMILIES = {**{f"positioning, {layout}": positioning_family(layout)
               for layout in syn.NULL_LAYOUTS},
            "tracking, 2 s at 1 ms, encoder noise (white + AR(1))": tracking_family(None),
            **{f"tracking, 2 s at 1 ms, {family}": tracking_family(family)
               for family in NOISE_FAMILIES}}


def clopper_pearson(alarms, trials, level=0.95):
    """Two-sided interval of a binomial rate."""
    tail = (1 - level) / 2
    low = stats.beta.ppf(tail, alarms, trials - alarms + 1) if alarms else 0.0
    high = stats.beta.ppf(1 - tail, alarms + 1, trials - alarms) if alarms < trials else 1.0
    return low, high


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=200, help="nulls per family (default 200)")
    parser.add_argument("--only", default="", help="run the families whose name contains this")
    args = parser.parse_args(argv)
    print(f"family-wise error rate of a whole diagnosis, every kind: {FAMILY_ALPHA:g}")
    with tempfile.TemporaryDirectory() as folder:
        for seed, (name, family) in enumerate(FAMILIES.items()):
            if args.only not in name:
                continue
            started = time.perf_counter()
            alarms = family(args.trials, seed, folder)
            low, high = clopper_pearson(alarms, args.trials)
            print(f"{name}: {alarms} false alarms in {args.trials} nulls "
                  f"({100 * alarms / args.trials:.2f} %, 95 % interval {100 * low:.2f}-"
                  f"{100 * high:.2f} %; {time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
