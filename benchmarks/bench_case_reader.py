"""The case reader against NumPy's own CSV reader (issue 25 item 3).

Run: ``python benchmarks/bench_case_reader.py [--rows 1000000] [--repeats 5] [--smoke]``. Writes one
positioning.csv (target_mm, error_um, direction, run: the ISO 230-2 layout) and times
``feedaxis.measurement.positioning.read_positioning`` (decoding, the header, NumPy's parse, every check of
docs/case-format.md) against a bare ``np.loadtxt`` of the same file, in interleaved repeats;
prints the medians (with their range) and the ratio. The target is a ratio <= 1.5.
"""
import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from feedaxis.measurement.positioning import read_positioning

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments  # noqa: E402


def write_positioning(path, rows, seed=1):
    """A positioning.csv of ``rows`` samples: 5 runs over equally spaced targets, both
    directions, deviations as a laser writes them (full float precision)."""
    rng = np.random.default_rng(seed)
    target_mm = np.round(np.linspace(0.0, 500.0, max(rows // 10, 2)), 3)
    index = np.arange(rows)
    columns = [target_mm[index % target_mm.size], rng.normal(0.0, 3.0, rows),
               np.where(index % 2 == 0, 1, -1), 1 + index % 5]
    lines = ["target_mm,error_um,direction,run"] + [
        f"{t!r},{e!r},{int(d):+d},{int(r)}" for t, e, d, r in zip(*(c.tolist() for c in columns))]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def timed(call):
    start = time.perf_counter()
    call()
    return time.perf_counter() - start


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = arguments(parser, argv, rows=300, repeats=1)
    with tempfile.TemporaryDirectory() as folder:
        path = write_positioning(Path(folder) / "positioning.csv", args.rows)
        reader, numpy = [], []
        for _ in range(args.repeats):
            reader.append(timed(lambda: read_positioning(path)))
            numpy.append(timed(lambda: np.loadtxt(path, delimiter=",", skiprows=1)))
        ratios = [r / n for r, n in zip(reader, numpy)]
    print(f"{args.rows} rows x 4 columns, {args.repeats} interleaved repeats")
    print(f"  read_positioning: {statistics.median(reader):.3f} s "
          f"({min(reader):.3f}-{max(reader):.3f})")
    print(f"  np.loadtxt:       {statistics.median(numpy):.3f} s "
          f"({min(numpy):.3f}-{max(numpy):.3f})")
    print(f"  reader / np.loadtxt = {statistics.median(ratios):.2f} "
          f"(pairs {min(ratios):.2f}-{max(ratios):.2f}; target <= 1.5)")


if __name__ == "__main__":
    main()
