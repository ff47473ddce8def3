"""Long thermal duties: `fit --add thermal_screw` on a 10^6-segment duty.csv, and one evaluation of the field against the segment-by-segment path.

The case: a duty.csv of 10^6 one-second rows (11.6 days logged at 1 s) in which the axis
keeps one program for a while (runs of 1 to 600 rows: one of six paths at one of three
feeds, or standing still), a positioning pass over 11 targets every 2 hours (time_s),
errors from Eq. 10 of the thermal paper with its Table 3 X coefficients (P_f -141 mm) plus
a lead error and 1 µm noise.

In one run it times

- one evaluation of the thermal field at the samples (``thermal.duty_unit_fields``):
  run by run (consecutive rows of one path and feed advanced as one, the field formed at
  the sample times only) against segment by segment (each row's closed form from the
  field the one before left, what it was before; timed on the first
  ``--baseline-segments`` rows and scaled linearly to the whole duty, its cost per row
  being constant) and their largest difference on those rows;
- ``feedaxis fit CASE --add thermal_screw`` end to end in a fresh process (reading the
  case included): wall and CPU time, peak resident memory, and the last count its
  progress bar showed against the bar's total (the most evaluations the fits can make).

Run: ``python benchmarks/bench_thermal_duty.py [--segments 1000000] [--repeats 3]``.
Medians (and min-max) of the repeats.
"""
import argparse
import os
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
sys.path.insert(0, str(HERE.parent / "tests" / "physics"))  # test_thermal_duty
sys.path.insert(0, str(HERE))

from common import arguments, run_command  # noqa: E402
from feedaxis.case import read_case, write_case  # noqa: E402
from feedaxis.examples import TABLE2_AXIS, TABLE2_LEAD  # noqa: E402
from feedaxis.physics import geometry, thermal  # noqa: E402
from test_thermal_duty import stepwise_unit_fields  # noqa: E402

TIME_TARGET_S = 30.0
FEEDS_MM_MIN = (1500.0, 3000.0, 6000.0)
STROKES_MM = ((0.0, 500.0), (0.0, 250.0), (250.0, 500.0), (100.0, 400.0), (0.0, 100.0),
              (400.0, 500.0))


def duty_columns(segments, seed=1):
    """duty.csv's columns: ``segments`` one-second rows in runs of 1-600 rows of one program
    (a stroke at a feed, or standing still at the stroke's start, a third of the time)."""
    rng = np.random.default_rng(seed)
    lengths = rng.integers(1, 601, segments // 300 + 2)
    lengths = lengths[:np.searchsorted(np.cumsum(lengths), segments) + 1]
    lengths[-1] -= lengths.sum() - segments
    stroke = rng.integers(len(STROKES_MM), size=lengths.size)
    feed = np.where(rng.random(lengths.size) < 1 / 3, 0.0,
                    np.take(FEEDS_MM_MIN, rng.integers(len(FEEDS_MM_MIN), size=lengths.size)))
    from_mm, to_mm = np.array(STROKES_MM)[stroke].T
    to_mm = np.where(feed > 0, to_mm, from_mm)
    return {"start_s": np.arange(float(segments)), "duration_s": np.ones(segments),
            "feed_mm_min": np.repeat(feed, lengths), "from_mm": np.repeat(from_mm, lengths),
            "to_mm": np.repeat(to_mm, lengths)}


def write_duty_case(folder, segments, seed=1):
    """The case folder: axis.toml (Table 1 screw), duty.csv and positioning.csv."""
    duty = duty_columns(segments, seed)
    targets_mm = np.arange(0.0, 501.0, 50.0)
    starts_s = np.arange(0.0, segments - 3.0 * targets_mm.size, 7200.0)
    time_s = (starts_s[:, None] + 3.0 * np.arange(targets_mm.size)).ravel()
    target_mm = np.tile(targets_mm, starts_s.size)
    params = thermal.ThermalScrewParams()
    rise_K = thermal.simulate_duty(params, thermal.Segments(*duty.values()), time_s)
    error_um = (thermal.thermal_error_um(params, rise_K, target_mm)
                + geometry.lead_error_um(target_mm, **TABLE2_LEAD)
                + np.random.default_rng(seed).normal(0.0, 1.0, target_mm.size))
    write_case(folder, TABLE2_AXIS, duty=duty, positioning={
        "target_mm": target_mm, "error_um": np.round(error_um, 4), "time_s": time_s})


def timed(job, repeats):
    """(median, min, max) seconds of ``repeats`` calls."""
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        job()
        seconds.append(time.perf_counter() - start)
    return statistics.median(seconds), min(seconds), max(seconds)


def evaluation(folder, repeats, baseline_segments):
    """Print one field evaluation run by run against segment by segment."""
    case = read_case(folder)
    segments, times_s = case.duty.segments, np.unique(case.positioning.time_s)
    params = thermal.ThermalScrewParams()
    runs = thermal.Segments.of(segments).run_first.size
    fast = timed(lambda: thermal.duty_unit_fields(params, segments, times_s), repeats)
    head = thermal.Segments(*(column[:baseline_segments] for column in (
        segments.start_s, segments.duration_s, segments.feed_mm_min, segments.from_mm,
        segments.to_mm)))
    head_times_s = times_s[times_s <= head[-1].end_s]
    slow = timed(lambda: stepwise_unit_fields(params, head, head_times_s), 1)
    scale = len(segments) / len(head)
    difference = np.abs(thermal.duty_unit_fields(params, head, head_times_s)
                        - stepwise_unit_fields(params, head, head_times_s)).max()
    largest = np.abs(stepwise_unit_fields(params, head, head_times_s)).max()
    print(f"{len(segments):,} segments in {runs:,} runs of one path and feed, "
          f"{len(thermal.Segments.of(segments).keys)} distinct; {times_s.size:,} sample times")
    print(f"one field evaluation, run by run:         {fast[0]:8.3f} s ({fast[1]:.3f}-{fast[2]:.3f})")
    print(f"one field evaluation, segment by segment: {slow[0] * scale:8.3f} s (timed on "
          f"{len(head):,} segments: {slow[0]:.3f} s, x {scale:g})")
    print(f"segment by segment / run by run: {slow[0] * scale / fast[0]:.0f}x; largest "
          f"difference on the {len(head):,} segments {difference / largest:.1e} of the largest rise")


def run_fit(folder):
    """(wall s, CPU s, peak RSS MB, the bar's last (count, total), the RMS line) of one
    ``feedaxis fit --add thermal_screw``."""
    done = run_command([sys.executable, "-m", "feedaxis", "fit", str(folder), "--add",
                        "thermal_screw"])
    shown = [(int(n), int(total)) for n, total in re.findall(r"(\d+)/(\d+) \[", done.stderr)]
    rms = re.search(r"RMS[^\n]*", done.stdout)
    return (done.wall_s, done.cpu_s, done.peak_mb, max(shown, default=None),
            rms.group(0) if rms else "")


def fitting(folder, repeats):
    """Print the whole ``fit --add thermal_screw`` command: wall and CPU time, peak memory,
    the progress bar's last count against its total."""
    runs = [run_fit(folder) for _ in range(repeats)]
    walls, cpus = [r[0] for r in runs], [r[1] for r in runs]
    print(f"feedaxis fit --add thermal_screw: wall {statistics.median(walls):.1f} s "
          f"({min(walls):.1f}-{max(walls):.1f}), {statistics.median(walls) / TIME_TARGET_S:.2f} "
          f"of the {TIME_TARGET_S:g} s target; CPU {statistics.median(cpus):.1f} s "
          f"({min(cpus):.1f}-{max(cpus):.1f}); peak RSS {max(r[2] for r in runs):.0f} MB")
    shown = runs[-1][3]
    print(f"  progress bar: {'%d of a total of %d evaluations' % shown if shown else 'not shown'}"
          f"; {runs[-1][4]}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--segments", type=int, default=1_000_000)
    parser.add_argument("--baseline-segments", type=int, default=50_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = arguments(parser, argv, segments=20_000, baseline_segments=2_000, repeats=1)
    print(f"load average {', '.join(f'{v:.1f}' for v in os.getloadavg())} "
          f"on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as work:
        folder = Path(work) / "long-duty"
        write_duty_case(folder, args.segments)
        evaluation(folder, args.repeats, args.baseline_segments)
        fitting(folder, args.repeats)


if __name__ == "__main__":
    main()
