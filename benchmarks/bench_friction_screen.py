"""The friction laws' score screen (feedaxis.diagnose.SCREEN_ALPHA): its rates, and that it
never hides a friction the full fit would name.

Before it fits a friction law on top of a model holding the plant, the diagnosis screens the
law by its score test: the diagnosis's own F test (effective sample count n/τ) on the drop one
Gauss-Newton step gives from the law's neutral values (no friction) over the model's Jacobian
and the law's exact sensitivities. Only where that test passes at ``SCREEN_ALPHA`` is the law
fitted in full and judged by the full fit's test as before.

For each family of seeded records (the PID of tests/tracking_synthetic.py on 2 s of two
sines; the four cascades of tests/cascade_synthetic.py on 3 s of the exciting reference;
encoder noise white 0.1 µm + AR(1) 0.3 µm) and each friction size (0: the null), over
``--seeds`` seeds, the plant is fitted as the diagnosis fits its base, then each law
(Coulomb, Stribeck) is both screened and fitted in full:

- screen passes: the share whose screen p-value is below SCREEN_ALPHA (on the null, its false
  alarm rate: the fits the screen does not save; with friction, its power);
- full named: the share whose full fit passes the policy's level (FAMILY_ALPHA over 3 stages
  and 4 effects tried, as a diagnosis of a model holding the plant tries them);
- missed: the records where the full fit passes that level but the screen does not (a
  friction the screen would hide: it must be 0); beside it the largest screen p-value
  among the records the full fit names (the margin below SCREEN_ALPHA).

Run: ``python benchmarks/bench_friction_screen.py [--seeds 25]`` (``--smoke``: one seed).
"""
import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from cascade_synthetic import cascade_loop, exciting, write_cascade_case  # noqa: E402
from common import arguments, clopper_pearson, machine  # noqa: E402
from feedaxis.case import read_case  # noqa: E402
from feedaxis.diagnose import (SCREEN_ALPHA, Refitter, _extra_test, _fit,  # noqa: E402
                               _screened_residual)
from feedaxis.effects import CATALOG, Model  # noqa: E402
from feedaxis.fit import fit_with_artefacts  # noqa: E402
from feedaxis.measurement import measurement_of  # noqa: E402
from feedaxis.stats.judge import FAMILY_ALPHA, accepts  # noqa: E402
from tracking_synthetic import step_loop, two_sines, write_tracking_case  # noqa: E402

PLANT = {"plant_gain_mm_per_Vs2": 70000.0, "plant_damping_per_s": 150.0,
         "plant_stiffness_per_s2": 250.0, "delay_s": 0.0015}
LAWS = ("coulomb_friction", "stribeck_friction")
TRIED, STAGES = 4, 3  # effects a diagnosis of a model holding the plant tries; its stages
# friction sizes (N) around each family's detection limit; Stribeck records rise to twice
# the Coulomb level at rest over 2 mm/s
SIZES = {"PID": (0.0, 0.005, 0.01, 0.02, 0.05, 0.2, 1.5),
         "P-P": (0.0, 0.02, 0.05, 0.1, 0.3, 3.0),
         "P-P ff": (0.0, 0.02, 0.05, 0.1, 0.3, 3.0),
         "P-PI": (0.0, 0.02, 0.05, 0.1, 0.3, 3.0),
         "P-PI ff": (0.0, 0.02, 0.05, 0.1, 0.3, 3.0)}


def record(folder, family, law, size_N, seed):
    """A seeded case of ``family`` with ``size_N`` of friction of ``law``."""
    friction = ({"friction_N": size_N} if law == "coulomb_friction" else
                {"coulomb_N": size_N, "static_N": 2.0 * size_N, "stribeck_velocity_mm_s": 2.0})
    path = Path(folder) / f"{family}-{law}-{size_N}-{seed}"
    if family == "PID":
        if law == "coulomb_friction":
            run = step_loop(two_sines, 2.0, plant=PLANT, friction_N=size_N)
        else:
            return None  # the RK4 PID generator has Coulomb friction only
        return read_case(write_tracking_case(path, run, seed))
    return read_case(write_cascade_case(path, cascade_loop(exciting, 3.0, family, **friction),
                                        family, seed))


def screened_and_full(case):
    """{law: (screen p-value, full fit's p-value)} on top of servo_plant fitted as the
    diagnosis's base."""
    measurement = measurement_of(case, "tracking")
    measurement.refitter = Refitter(measurement, CATALOG)
    left = fit_with_artefacts(Model((CATALOG["servo_plant"],)), measurement)
    measurement = left.measurements[0]
    found = {}
    for law in LAWS:
        effect = CATALOG[law]
        extra = len(effect.parameters)
        screen = _extra_test(measurement, left,
                             _screened_residual(measurement, left, effect, exact=True), extra)
        full = _extra_test(measurement, left, _fit(left.model + effect, measurement).residual_um,
                           extra)
        found[law] = (screen.p_value, full.p_value)
    return found


def rates(folder, seeds):
    """{(family, law, size): {law tested: [(screen p, full p)]}} over ``seeds``."""
    table = {}
    for family, sizes in SIZES.items():
        for law in LAWS:
            for size_N in sizes:
                if size_N == 0.0 and law != LAWS[0]:
                    continue  # one null per family
                rows = {tested: [] for tested in LAWS}
                for seed in range(seeds):
                    case = record(folder, family, law, size_N, 100 + seed)
                    if case is None:
                        break
                    for tested, pair in screened_and_full(case).items():
                        rows[tested].append(pair)
                if rows[LAWS[0]]:
                    table[(family, "none" if size_N == 0.0 else law, size_N)] = rows
    return table


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=25)
    args = arguments(parser, argv, seeds=1)
    if args.smoke:
        for family in SIZES:
            SIZES[family] = SIZES[family][:2]
    level = FAMILY_ALPHA / STAGES / TRIED
    print(machine())
    print(f"screen level {SCREEN_ALPHA}; a law is named at p < {level:.3g} "
          f"({FAMILY_ALPHA} over {STAGES} stages and {TRIED} effects)")
    print(f"{'family':8s} {'friction':18s} {'size N':>7s} {'law tested':18s} "
          f"{'screen passes':>14s} {'full named':>11s} {'missed':>7s} "
          f"{'screen p, named':>16s}")
    missed_total = trials_total = 0
    largest = 0.0
    null_passes = null_trials = 0
    with tempfile.TemporaryDirectory() as folder, threadpool_limits(limits=1, user_api="blas"):
        for (family, law, size_N), rows in rates(folder, args.seeds).items():
            for tested, pairs in rows.items():
                screen = np.array([p for p, _ in pairs])
                full = np.array([q for _, q in pairs])
                passes = screen < SCREEN_ALPHA
                named = np.array([accepts(q, TRIED, STAGES) for q in full])
                missed = int(np.sum(named & ~passes))
                missed_total += missed
                trials_total += int(named.sum())
                if law == "none":
                    null_passes += int(passes.sum())
                    null_trials += passes.size
                worst = float(np.max(screen[named])) if named.any() else None
                largest = max(largest, worst or 0.0)
                print(f"{family:8s} {law:18s} {size_N:7.3g} {tested:18s} "
                      f"{passes.mean():14.2f} {named.mean():11.2f} {missed:7d} "
                      f"{'-' if worst is None else f'{worst:.2g}':>16s}")
    low, high = clopper_pearson(null_passes, null_trials)
    print(f"null: the screen passed {null_passes} of {null_trials} law tests "
          f"({100 * null_passes / max(null_trials, 1):.1f} %, 95 % interval "
          f"{100 * low:.1f}-{100 * high:.1f} %) at level {SCREEN_ALPHA}")
    print(f"missed: {missed_total} of the {trials_total} law tests the full fit named "
          f"(must be 0); the largest screen p-value among them {largest:.2g}")


if __name__ == "__main__":
    main()
