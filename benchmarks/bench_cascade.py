"""The loop on a drive's trace, and identification from its recorded controller output.

1. The loop a commissioning engineer runs on a 25 s record at 1 kHz of a P-PI cascade with
   velocity feed-forward and hidden Coulomb friction (tests/cascade_synthetic.py, encoder
   noise white 0.1 µm + AR(1) 0.3 µm): ``diagnose`` from the empty model (the start
   identified from the record), ``fit`` with the effects named added, ``diagnose`` again,
   until nothing more is named (at most three rounds). Target: 10 s. Timed beside the
   paths before the loop's sensitivities (forward-difference Jacobians, every fit of a
   diagnosis made anew: ``common.slow_tracking_paths``), interleaved, wall and CPU time.
2. ``identify_plant`` (inverse dynamics on control_V) on 10^5 samples. Target: 0.1 s.

Each is timed ``--repeats`` times; medians and their ratio to the target are printed side
by side (the machine is shared: medians, not single runs; CPU time is the fairer figure
under load).

Run: ``python benchmarks/bench_cascade.py [--repeats 5]``.
"""
import argparse
import contextlib
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from cascade_synthetic import (FORCE_CONSTANT_N_PER_V, cascade_loop, exciting,  # noqa: E402
                               write_cascade_case)
from common import (arguments, machine, ratio_lines, side_by_side,  # noqa: E402
                    slow_tracking_paths)
from feedaxis.case import read_case  # noqa: E402
from feedaxis.diagnose import diagnose  # noqa: E402
from feedaxis.effects import CATALOG, Model  # noqa: E402
from feedaxis.fit import fit  # noqa: E402
from feedaxis.physics.identify import identify_plant  # noqa: E402

LOOP_TARGET_S = 10.0
IDENTIFY_TARGET_S = 0.1
CASCADE = "P-PI ff"


def the_loop(folder):
    """Effects named in order by diagnose / fit --add / diagnose until done, on a freshly
    read case (nothing cached from an earlier run)."""
    case = read_case(folder)
    model, named = Model(), []
    for _ in range(3):
        found = diagnose(case, model)
        if not found.candidates:
            break
        for candidate in found.candidates:
            named.append(candidate.effect)
            model = model + CATALOG[candidate.effect]
        model = fit(model, case).model
    return named


def identification(samples):
    """Seconds of one identification on ``samples`` samples of a cascade record."""
    time_s, position_mm, control_V = samples
    started = time.perf_counter()
    found = identify_plant(time_s, position_mm, control_V, FORCE_CONSTANT_N_PER_V)
    elapsed = time.perf_counter() - started
    assert found is not None
    return elapsed


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed runs of each (default 5)")
    parser.add_argument("--duration-s", type=float, default=25.0,
                        help="length of the loop's record (default 25 s)")
    parser.add_argument("--samples", type=int, default=100_000,
                        help="samples of the identification (default 1e5)")
    args = arguments(parser, argv, repeats=1, duration_s=2.0, samples=5_000)
    print(machine())
    with tempfile.TemporaryDirectory() as scratch:
        record = cascade_loop(exciting, args.duration_s, CASCADE, friction_N=5.0)
        folder = write_cascade_case(Path(scratch) / "trace", record, CASCADE, 1)
        the_loop(folder)  # compiles and caches the kernels once
        loops = side_by_side({"sensitivities, fits kept": (contextlib.nullcontext,
                                                           lambda: the_loop(folder)),
                              "differences, every fit anew": (slow_tracking_paths,
                                                              lambda: the_loop(folder))},
                             args.repeats)
    long_record = cascade_loop(exciting, (args.samples - 1) * 1e-3, CASCADE, friction_N=5.0)
    noisy = (long_record[0],
             long_record[2] + np.random.default_rng(1).normal(0.0, 3e-5, long_record[0].size),
             long_record[3])
    identification(noisy)
    identifications = [identification(noisy) for _ in range(max(args.repeats, 5))]
    walls, cpus, named = loops["sensitivities, fits kept"]
    identify_s = statistics.median(identifications)
    print(f"the loop on {args.duration_s:g} s at 1 kHz ({CASCADE}, Coulomb friction hidden), "
          f"effects named {' + '.join(named) or 'none'} (before: "
          f"{' + '.join(loops['differences, every fit anew'][2]) or 'none'}):")
    print("\n".join(ratio_lines(loops, "sensitivities, fits kept",
                                "differences, every fit anew")))
    print(f"  median {statistics.median(walls):.2f} s wall, {statistics.median(cpus):.2f} s "
          f"CPU: {statistics.median(cpus) / LOOP_TARGET_S:.2f} of the {LOOP_TARGET_S:g} s "
          f"target in CPU time")
    print(f"identification from control_V on {args.samples} samples: median "
          f"{1e3 * identify_s:.1f} ms over {len(identifications)} runs, "
          f"{identify_s / IDENTIFY_TARGET_S:.2f} of the {1e3 * IDENTIFY_TARGET_S:g} ms target")


if __name__ == "__main__":
    main()
