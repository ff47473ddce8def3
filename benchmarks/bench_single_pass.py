"""False alarms and power of the diagnosis on one + and one - pass per target (issue 33).

An acceptance test often holds one pass each way: the + and - readings at a target are
then the only replicates (:class:`feedaxis.stats.noise.PureError`, paired, about a reversal
constant or linear along the travel where the pairs show it), their noise looked for along
the travel (:class:`feedaxis.stats.noise.SerialPairs`). Per family of
``tests/synthetic.SINGLE_PASS_FAMILIES`` (11 to 21 targets over 600 mm, even or unequal
spacing, a pair scatter of 4.1 µm, white, Student-t or AR(1) noise in the order taken,
reversals that scatter or change along the travel, a bow, the deviations at an arbitrary
zero), ``diagnose`` from the empty model: the share naming lead_error (a false alarm in a
null, the power in a trend of -16.9 µm over the travel), naming any other catalog effect
than lead_error and backlash or a periodic structure, and the share left ``undetermined``.
Each rate with its 95 % Clopper-Pearson interval.

Run: ``python benchmarks/bench_single_pass.py [--trials 200]``; ``--smoke``: 2 trials.
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import synthetic as syn  # noqa: E402
from common import arguments, rate  # noqa: E402
from feedaxis.diagnose import diagnose  # noqa: E402
from feedaxis.effects import Model  # noqa: E402


def family_rates(options, trials, seed):
    """(lead_error named, another effect or a periodic structure named, undetermined)."""
    rng = np.random.default_rng(seed)
    lead = other = undetermined = 0
    for _ in range(trials):
        found = diagnose(syn.single_pass_trial(rng, **options), Model())
        named = {c.effect for c in found.candidates}
        lead += "lead_error" in named
        other += bool(named - {"lead_error", "backlash"}) or any(
            s.kind == "periodic" for s in found.unexplained)
        undetermined += found.verdict == "undetermined"
    return lead, other, undetermined


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=200, help="cases per family (default 200)")
    args = arguments(parser, argv, trials=2)
    print(f"{'family':46s} {'lead_error named':>30s}   {'other named':>30s}   "
          f"{'undetermined':>30s}")
    for seed, (family, options) in enumerate(syn.SINGLE_PASS_FAMILIES.items(), start=500):
        started = time.process_time()
        counts = family_rates(options, args.trials, seed)
        print(f"{family:46s} " + "   ".join(f"{rate(c, args.trials):>30s}" for c in counts)
              + f"   {time.process_time() - started:.0f} s CPU", flush=True)


if __name__ == "__main__":
    main()
