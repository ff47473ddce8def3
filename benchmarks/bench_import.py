"""Wide-CSV import against its size (issue 26): linear in the rows, not quadratic.

Run: ``python benchmarks/bench_import.py [--rows 10000] [--repeats 3] [--smoke]``. Times
``feedaxis.importers.import_case`` (read, check, write the case, read it back) on a wide CSV
of ROWS targets and of 10 x ROWS, interleaved; prints the medians and their ratio: about 10
when the import is linear (before issue 26, a list search per target made it about 100:
10^4 rows 1.3 s, 10^5 rows 60 s).
"""
import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from feedaxis.importers import import_case

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments  # noqa: E402


def write_wide_csv(path, rows):
    """``rows`` targets 0.01 mm apart, two runs in both directions, deviations in µm."""
    rng = np.random.default_rng(3)
    deviation_um = rng.normal(0.0, 2.0, (rows, 4)).round(4)
    lines = ["target_mm,run1+,run1-,run2+,run2-"] + [
        f"{i * 0.01:.2f}," + ",".join(map(repr, row))
        for i, row in enumerate(deviation_um.tolist())]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = arguments(parser, argv, rows=50, repeats=1)
    sizes = (args.rows, 10 * args.rows)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        (folder / "axis.toml").write_text("[screw]\nlead_mm = 5.0\n")
        sources = {n: write_wide_csv(folder / f"wide{n}.csv", n) for n in sizes}
        times = {n: [] for n in sizes}
        for repeat in range(args.repeats):
            for n in sizes:
                out = folder / f"case{n}-{repeat}"
                start = time.perf_counter()
                import_case(sources[n], folder / "axis.toml", out)
                times[n].append(time.perf_counter() - start)
    small, large = (statistics.median(times[n]) for n in sizes)
    for n in sizes:
        print(f"  {n:>8} rows: {statistics.median(times[n]):.3f} s "
              f"({min(times[n]):.3f}-{max(times[n]):.3f}), "
              f"{1e6 * statistics.median(times[n]) / n:.1f} us per row")
    print(f"  10x the rows takes {large / small:.1f}x the time (linear: about 10; "
          "quadratic: about 100)")


if __name__ == "__main__":
    main()
