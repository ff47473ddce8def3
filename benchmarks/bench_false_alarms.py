"""False alarms and power of the one diagnosis, for every kind of measurement.

The family-wise error rate of a whole diagnosis under the complete null is 0.001 for every
kind (``feedaxis.stats.judge``: split over the measurement's stages, Bonferroni over the
terms tried). This benchmark measures it on nulls whose model is the truth (lead error),
per null family of ``tests/synthetic.NULL_FAMILIES``: two layouts (an ISO 230-2 test of 21
targets x 5 bidirectional runs, 210 samples; a dense single pass every 1 mm over 500 mm)
times white noise, AR(1) with ρ 0.5, 0.9, 0.95 in the order taken, Student-t with 3
degrees of freedom, Gaussian quantised to 0.1 µm, a drift along the test's clock, two
±3 µm outliers (σ = 0.3 µm). A false alarm is a catalog effect named or a periodic
structure described (the issue's definition), counted apart from any other structure named
(a drift where the null does not drift, a trend, an irregular error): both are printed.
Tracking: 2 s records at 1 ms of the plant of ``tests/fit_diagnosis/test_tracking_loop.py``, model
servo_plant at the truth, with encoder noise (white 0.1 µm + AR(1) 0.3 µm) and each null
family of ``tests/tracking_synthetic.NOISE_FAMILIES`` (white; AR(1) with ρ 0.5 and 0.95;
Student-t with 3 degrees of freedom; quantised to 0.1 µm; a slow drift, the tracking
diagnosis's nuisance; three single-sample spikes of 5-20 µm, its outliers); the share of
nulls with outliers left out is printed and, for the spikes, the share where exactly the
spikes were found.

Cascade drives (``--only cascade``): 2 s records at 1 ms of the four cascades of
``tests/cascade_synthetic.py`` (P-P and P-PI, with and without velocity feed-forward), the
encoder noise above, diagnosed from the empty model (the start identified from the record:
the path a drive's trace takes), each cascade without and with the recorded controller
output (control_V): eight families; a false alarm is any effect named or any structure
described, a drift alone (the nuisance's own liberal test at ρ = 0.95) counted apart.

Power: ISO 230-2 cases with a backlash B (0.3 µm noise, 105 pairs): the share of trials in
which ``diagnose`` names backlash first against the share in which a plain paired t-test
of x(+) - x(-) gives p < 0.001, and the smallest B each finds with 95 % power.

Run: ``python benchmarks/bench_false_alarms.py [--trials 200] [--power-trials 200]
[--only tracking]``; each
rate with its 95 % Clopper-Pearson interval. ``--trials 2 --power-trials 2`` is the CI smoke
run.
"""
import argparse
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import synthetic as syn  # noqa: E402
from common import arguments, rate  # noqa: E402
from feedaxis.case import read_case  # noqa: E402
from feedaxis.diagnose import diagnose  # noqa: E402
from feedaxis.effects import CATALOG, Model  # noqa: E402
from feedaxis.measurement import Tracking  # noqa: E402
from feedaxis.stats.judge import FAMILY_ALPHA  # noqa: E402
from cascade_synthetic import (CASCADES, cascade_loop, exciting,  # noqa: E402
                               write_cascade_case)
from tracking_synthetic import (NOISE_FAMILIES, spike_indices, step_loop,  # noqa: E402
                                two_sines, write_tracking_case)

LEAD = Model([CATALOG["lead_error"]])
PLANT = {"plant_gain_mm_per_Vs2": 70000.0, "plant_damping_per_s": 150.0,
         "plant_stiffness_per_s2": 250.0, "delay_s": 0.0015}
BACKLASH_GRID_UM = np.round(np.arange(0.05, 0.351, 0.05), 3)


def positioning_alarms(family, trials, seed):
    """(catalog effect or periodic structure named, other structure named) counts."""
    layout, options = syn.NULL_FAMILIES[family]
    rng = np.random.default_rng(seed)
    named = other = 0
    for _ in range(trials):
        found = diagnose(syn.null_trial(rng, layout, **options)[0], LEAD)
        kinds = [s.kind for s in found.unexplained
                 if not (options.get("drift") and s.kind == "drift")]
        named += bool(found.candidates) or "periodic" in kinds
        other += bool(kinds) and "periodic" not in kinds and not found.candidates
    return named, other


def tracking_alarms(family, trials, seed, folder):
    """(catalog effect or periodic structure named, other structure named, nulls with
    outliers left out, nulls where exactly the spikes were found) of one noise family
    (None: the encoder noise); a drift is the null's own only in the drifting family."""
    run = step_loop(two_sines, 2.0, plant=PLANT)
    model = Model([CATALOG["servo_plant"]], {"servo_plant": PLANT})
    named = other = with_outliers = spikes_found = 0
    for k in range(trials):
        noise_seed = seed * 100_000 + k
        case = read_case(write_tracking_case(Path(folder) / f"t{seed}-{k}", run, noise_seed,
                                             family=family))
        found = diagnose(case, model)
        kinds = [s.kind for s in found.unexplained
                 if not (family == "drifting" and s.kind == "drift")]
        named += bool(found.candidates) or "periodic" in kinds
        other += bool(kinds) and "periodic" not in kinds and not found.candidates
        with_outliers += bool(found.outlier_rows)
        if family == "spikes":
            spikes = spike_indices(run[0].size, noise_seed)
            compared = spikes[np.isin(spikes, Tracking(case).index)]
            spikes_found += found.outlier_rows == (compared + 2).tolist()
    return named, other, with_outliers, spikes_found


TRACKING_FAMILIES = ("encoder (white + AR(1))", *NOISE_FAMILIES)


def cascade_alarms(cascade, control, trials, seed, folder):
    """(nulls with an effect named or a structure other than a drift described, nulls with
    only a drift (the nuisance's own test), what the alarms named) of one cascade of
    :data:`cascade_synthetic.CASCADES`, with or without the recorded ``control`` output,
    from the empty model."""
    record = cascade_loop(exciting, 2.0, cascade)
    alarms = drifts = 0
    named = Counter()
    for k in range(trials):
        case = read_case(write_cascade_case(Path(folder) / f"c{seed}-{k}", record, cascade,
                                            seed * 100_000 + k, control))
        found = diagnose(case, Model())
        kinds = [s.kind for s in found.unexplained if s.kind != "drift"]
        alarm = bool(found.candidates or kinds)
        alarms += alarm
        drifts += not alarm and bool(found.unexplained)
        named.update([c.effect for c in found.candidates] + kinds)
    return alarms, drifts, named


CASCADE_FAMILIES = [(cascade, control) for cascade in CASCADES for control in (False, True)]


def smallest_with_power(grid, power, target=0.95):
    """Linear interpolation of the first crossing of ``target``; NaN when never reached."""
    above = np.flatnonzero(np.asarray(power) >= target)
    if above.size == 0:
        return float("nan")
    i = above[0]
    if i == 0:
        return float(grid[0])
    return float(np.interp(target, [power[i - 1], power[i]], [grid[i - 1], grid[i]]))


PARTS = ("positioning", "tracking", "cascade", "power")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=200, help="nulls per family (default 200)")
    parser.add_argument("--power-trials", type=int, default=200,
                        help="trials per backlash of the power curve (default 200)")
    parser.add_argument("--only", action="append", choices=PARTS,
                        help="run only this part (repeatable; default all: "
                             + ", ".join(PARTS) + ")")
    args = arguments(parser, argv, trials=2, power_trials=2)
    parts = args.only or PARTS
    print(f"family-wise error rate of a whole diagnosis, every kind: {FAMILY_ALPHA:g}")
    print(f"{'null family':30s} {'effect or periodic named':>34s}   {'other structure named':>34s}")
    for seed, family in enumerate(syn.NULL_FAMILIES if "positioning" in parts else ()):
        started = time.perf_counter()
        named, other = positioning_alarms(family, args.trials, seed)
        print(f"{family:30s} {rate(named, args.trials):>34s}   {rate(other, args.trials):>34s}"
              f"   {time.perf_counter() - started:.0f} s", flush=True)
    with tempfile.TemporaryDirectory() as folder:
        for seed, family in enumerate(TRACKING_FAMILIES if "tracking" in parts else (),
                                      start=99):
            started = time.perf_counter()
            named, other, outliers, spikes = tracking_alarms(
                None if family.startswith("encoder") else family, args.trials, seed, folder)
            found = f", the spikes exactly in {spikes}" if family == "spikes" else ""
            print(f"{'tracking, ' + family:30s} {rate(named, args.trials):>34s}   "
                  f"{rate(other, args.trials):>34s}   {time.perf_counter() - started:.0f} s "
                  f"(outliers left out in {outliers}{found})", flush=True)
        total = 0
        for seed, (cascade, control) in enumerate(
                CASCADE_FAMILIES if "cascade" in parts else (), start=199):
            started = time.perf_counter()
            alarms, drifts, named = cascade_alarms(cascade, control, args.trials, seed,
                                                   folder)
            total += alarms
            name = f"cascade {cascade}{', control_V' if control else ''}"
            print(f"{name:30s} {rate(alarms, args.trials):>34s}   {rate(drifts, args.trials):>34s}"
                  f"   {time.perf_counter() - started:.0f} s {dict(named) or ''}", flush=True)
        if "cascade" in parts:
            nulls = args.trials * len(CASCADE_FAMILIES)
            print(f"{'cascade, all families':30s} {rate(total, nulls):>34s}")
    if "power" in parts:
        backlash_power(args.power_trials)


def backlash_power(trials):
    """Print the power curve of naming a backlash against the paired t-test."""
    print(f"{'B (µm)':>8s} {'diagnose':>10s} {'paired t':>10s}")
    named, t_test = [], []
    for i, backlash_um in enumerate(BACKLASH_GRID_UM):
        power = syn.backlash_power(diagnose, LEAD, backlash_um, trials, seed=100 + i)
        named.append(power[0])
        t_test.append(power[1])
        print(f"{backlash_um:8.3f} {power[0]:10.3f} {power[1]:10.3f}", flush=True)
    b_diagnose = smallest_with_power(BACKLASH_GRID_UM, named)
    b_t_test = smallest_with_power(BACKLASH_GRID_UM, t_test)
    print(f"smallest B with 95 % power: diagnose {b_diagnose:.3f} µm, paired t-test "
          f"{b_t_test:.3f} µm, ratio {b_diagnose / b_t_test:.2f} (target <= 1.3)")


if __name__ == "__main__":
    main()
