"""Analysis at scale: diagnose and report on large cases against 5 s and 500 MB.

Cases (model: lead error, fitted first):
- positioning, 10^6 samples: 1,000 targets x 500 bidirectional runs, recorded targets
  jittered by ±1 nm (lead error, 0.5 µm backlash, 0.3 µm noise);
- the same 10^6 samples as a dense scan: 10^5 targets x 5 bidirectional runs (the shape
  dynamic capture gives; the cost should follow the samples, not the targets);
- a single pass over 10^5 uneven positions (lead error, 0.3 µm noise): diagnose and report;
- tracking, 500 s at 1 ms (500,000 samples, 5·10^6 loop steps per simulation) of Anang et al. 2017's
  loop on another plant, white + AR(1) noise; model servo_plant at the truth.
Wall time and CPU time (this process's, all threads: what the job costs on a quiet
machine, where a loaded one inflates the wall time): medians of ``--repeats`` runs, the
ratio to 5 s the wall time's; memory: peak of NumPy and Python allocations (tracemalloc)
during one more run, the case's own arrays excluded.

What each change bought on the dense scan (issue 35 item 1; CPU seconds of diagnose,
medians of 3, on the loaded 2-core machine; before them 5.1-5.2 s, 254 MB):

- the sandwich covariance's J'ΣJ (``feedaxis.stats.noise.spectral_gram``) transforms each
  Jacobian column once, holding up to 128 MB of transforms, instead of once per pair of
  columns (10 FFTs of 2^21 points instead of 31; the same products, so the same bits):
  5.1 -> 4.1 s, peak allocations 254 -> 282 MB;
- the serial-noise AR model by conditional least squares solves every order from one QR
  decomposition of the lagged samples, in blocks of 65,536 rows, instead of an SVD least
  squares per order on its own lagged copy (``least_squares_autoregression``; the same
  coefficients within 1e-13): 4.1 -> 3.2 s.

The 1,000 x 500 layout takes neither path (its residuals are white): 2.4-2.5 s before
and after.

The peak resident memory (RSS) against 500 MB is that of ``feedaxis diagnose`` run as the
user runs it, in a process of its own on the case read from disk (the kernel's ru_maxrss of
the child, measured before this process holds the cases: a child's starts from its
parent's), for the two 10^6-sample layouts; the in-process figures above hold every case at
once. Under ``/usr/bin/time`` (load 9): the dense scan 421 -> 380 MB, the 1,000-target
layout 321 -> 312 MB, before and after issue 35's bounded memory. What holds the dense
scan's: the interpreter with NumPy and SciPy (105 MB), the case's columns, indices and
residuals (about 100 MB), and at the peak the sandwich's J'ΣJ: its transforms (up to
``SPECTRA_BYTES``, 128 MB: six of 16 MB) and NumPy's padded copy in each FFT (32 MB).

Run: ``python benchmarks/bench_diagnose_scale.py [--repeats 3]``.
"""
import argparse
import statistics
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import synthetic as syn  # noqa: E402
from bench_positioning_scale import run, write_case_folder  # noqa: E402
from common import arguments  # noqa: E402
from feedaxis.analysis import analyse  # noqa: E402
from feedaxis.case import Axis, Case  # noqa: E402
from feedaxis.measurement.tracking import TrackingSamples  # noqa: E402
from feedaxis.diagnose import diagnose  # noqa: E402
from feedaxis.effects import CATALOG, Model  # noqa: E402
from feedaxis.fit import fit  # noqa: E402
from feedaxis.fmu_map import servo_to_fmu  # noqa: E402
from feedaxis.physics.servo import ServoParams, simulate  # noqa: E402
from feedaxis.report import write_report  # noqa: E402
from tracking_synthetic import AXIS, noise_um  # noqa: E402

TIME_TARGET_S = 5.0
MEMORY_TARGET_MB = 500.0
LEAD = Model([CATALOG["lead_error"]])
PLANT = {"plant_gain_mm_per_Vs2": 70000.0, "plant_damping_per_s": 150.0,
         "plant_stiffness_per_s2": 250.0, "delay_s": 0.0015}


def iso_like(samples, seed=1, n_targets=1000):
    return syn.in_memory_case(syn.ISO_AXIS, **iso_columns(samples, seed, n_targets))


def iso_columns(samples, seed=1, n_targets=1000):
    """{column: array} of ``samples`` rows: ``n_targets`` targets x bidirectional runs."""
    rng = np.random.default_rng(seed)
    runs = max(samples // (2 * n_targets), 1)
    targets = np.arange(n_targets) * 0.5 + rng.uniform(-0.1, 0.1, n_targets)
    run = np.repeat(np.arange(1, runs + 1), 2 * n_targets)
    target_mm = np.tile(np.concatenate((targets, targets[::-1])), runs)
    direction = np.tile(np.repeat([1.0, -1.0], n_targets), runs)
    target_mm = target_mm + rng.uniform(-1e-6, 1e-6, target_mm.size)
    error_um = (1.5 - 0.012 * target_mm + 0.25 * direction
                + rng.normal(0.0, 0.3, target_mm.size))
    return {"target_mm": target_mm, "error_um": error_um, "direction": direction, "run": run}


def single_pass(samples, seed=2):
    rng = np.random.default_rng(seed)
    target_mm = np.sort(rng.uniform(0.0, 500.0, samples))
    error_um = 1.5 - 0.012 * target_mm + rng.normal(0.0, 0.3, samples)
    return syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=error_um)


def tracking_trace(duration_s, seed=3):
    time_s = np.arange(0.0, duration_s, 1e-3)
    reference_mm = 10 * np.sin(np.pi * time_s) + 0.3 * np.sin(2 * np.pi * 7 * time_s)
    position_mm = simulate(ServoParams(**{**servo_to_fmu(AXIS["servo"]), **PLANT}), time_s,
                           reference_mm)
    actual_mm = position_mm + noise_um(time_s.size, seed) * 1e-3
    return Case(Path("generated"), Axis("trace", {"lead_mm": 10.0}, {}, dict(AXIS["servo"])),
                {"tracking": TrackingSamples(time_s, reference_mm, actual_mm)})


def measure(job, repeats):
    """(median, min, max wall s, median CPU s, peak MB) of ``job``."""
    times, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        job()
        times.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    tracemalloc.start()
    job()
    peak_mb = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return statistics.median(times), min(times), max(times), statistics.median(cpu), peak_mb


def jobs(args, folder):
    """{(case label, job): callable}."""
    positioning, single = iso_like(args.samples), single_pass(args.single_pass)
    dense = iso_like(args.samples, n_targets=args.samples // 10)
    trace = tracking_trace(args.tracking_s)
    positioning_model, single_model, dense_model = (fit(LEAD, case).model
                                                    for case in (positioning, single, dense))
    plant = Model([CATALOG["servo_plant"]], {"servo_plant": PLANT})
    report = Path(folder) / "report.html"
    return {
        (f"positioning, {positioning.positioning.size:,} samples", "diagnose"):
            lambda: diagnose(positioning, positioning_model),
        (f"dense scan, {dense.positioning.size:,} samples", "diagnose"):
            lambda: diagnose(dense, dense_model),
        (f"single pass, {single.positioning.size:,} samples", "diagnose"):
            lambda: diagnose(single, single_model),
        (f"single pass, {single.positioning.size:,} samples", "report"):
            lambda: write_report(analyse(single, single_model), report),
        (f"tracking, {args.tracking_s:g} s at 1 ms", "diagnose"):
            lambda: diagnose(trace, plant),
    }


def child_peaks(samples, repeats, folder):
    """{layout: (median CPU s, largest peak RSS MB)} of ``feedaxis diagnose`` in a process
    of its own on each 10^6-sample layout written to disk, its model fitted first."""
    peaks = {}
    for label, targets in (("positioning", 1000), ("dense scan", samples // 10)):
        case, model = Path(folder) / label / "case", str(Path(folder) / label / "model.toml")
        write_case_folder(case, samples, targets)
        run(["fit", str(case), "--add", "lead_error", "--out", model])
        done = [run(["diagnose", str(case), "--model", model]) for _ in range(repeats)]
        peaks[label] = (statistics.median(c.cpu_s for c in done), max(c.peak_mb for c in done))
    return peaks


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per job (default 3)")
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--single-pass", type=int, default=100_000)
    parser.add_argument("--tracking-s", type=float, default=500.0)
    args = arguments(parser, argv, repeats=1, samples=4_000, single_pass=2_000, tracking_s=3.0)
    with tempfile.TemporaryDirectory() as folder:
        # first, while this process is small: a child's ru_maxrss starts from its parent's
        peaks = child_peaks(args.samples, args.repeats, folder)
        work = jobs(args, folder)
        print(f"{'case':36s} {'job':9s} {'time (s)':>9s} {'(min-max)':>13s} {'/ 5 s':>6s} "
              f"{'CPU (s)':>8s} {'peak MB':>8s} {'/ 500 MB':>8s}")
        measured = {}
        for (label, name), job in work.items():
            seconds, low, high, cpu_s, peak_mb = measured[label.split(",")[0], name] = measure(
                job, args.repeats)
            print(f"{label:36s} {name:9s} {seconds:9.2f} {f'({low:.2f}-{high:.2f})':>13s} "
                  f"{seconds / TIME_TARGET_S:6.2f} {cpu_s:8.2f} {peak_mb:8.0f} "
                  f"{peak_mb / MEMORY_TARGET_MB:8.2f}", flush=True)
        dense, regular = measured["dense scan", "diagnose"], measured["positioning", "diagnose"]
        print(f"dense scan / the 1,000-target layout of the same samples: time "
              f"{dense[0] / regular[0]:.2f}, CPU {dense[3] / regular[3]:.2f}, memory "
              f"{dense[4] / regular[4]:.2f}")
        print(f"feedaxis diagnose in a process of its own, {args.samples:,} samples read from "
              f"disk (median CPU of {args.repeats}, largest peak RSS):")
        for label, (cpu_s, peak_mb) in peaks.items():
            print(f"  {label:12s} CPU {cpu_s:6.2f} s  peak RSS {peak_mb:5.0f} MB "
                  f"({peak_mb / MEMORY_TARGET_MB:.2f} of {MEMORY_TARGET_MB:.0f} MB)")


if __name__ == "__main__":
    main()
