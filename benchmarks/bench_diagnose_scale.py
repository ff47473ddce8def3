"""Diagnosis at scale (issue 10): ``diagnose`` and ``report`` on 10^5 samples whose recorded
targets carry jitter, against the targets of 5 s and 500 MB.

Cases (lead error + 0.5 µm backlash + 0.3 µm noise, model: lead_error):
- ISO-like: 1,000 targets x 50 bidirectional runs, recorded targets jittered by ±1 nm;
- the same with ±0.01 µm of jitter;
- a dense single pass over 100,000 uneven positions (no repeats).
Wall time: median of ``--repeats`` runs; memory: peak of NumPy and Python allocations
(tracemalloc) during one more run, imports excluded.

Run: ``python benchmarks/bench_diagnose_scale.py [--repeats 3]``.
"""
import argparse
import resource
import statistics
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

import synthetic as syn  # noqa: E402
from feedaxis.diagnose import diagnose  # noqa: E402
from feedaxis.effects import CATALOG, Model  # noqa: E402
from feedaxis.fit import fit  # noqa: E402
from feedaxis.report import write_report  # noqa: E402

TIME_TARGET_S = 5.0
MEMORY_TARGET_MB = 500.0
LEAD = Model([CATALOG["lead_error"]])


def iso_like(jitter_mm, seed=1, n_targets=1000, runs=50):
    rng = np.random.default_rng(seed)
    targets = np.arange(n_targets) * 0.5 + rng.uniform(-0.1, 0.1, n_targets)
    run = np.repeat(np.arange(1, runs + 1), 2 * n_targets)
    target_mm = np.tile(np.concatenate((targets, targets[::-1])), runs)
    direction = np.tile(np.repeat([1.0, -1.0], n_targets), runs)
    target_mm = target_mm + rng.uniform(-jitter_mm, jitter_mm, target_mm.size)
    error_um = (1.5 - 0.012 * target_mm + 0.25 * direction
                + rng.normal(0.0, 0.3, target_mm.size))
    return syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=error_um,
                              direction=direction, run=run)


def single_pass(seed=2, n=100_000):
    rng = np.random.default_rng(seed)
    target_mm = np.sort(rng.uniform(0.0, 500.0, n))
    error_um = 1.5 - 0.012 * target_mm + rng.normal(0.0, 0.3, n)
    return syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=error_um)


def measure(job, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        job()
        times.append(time.perf_counter() - start)
    tracemalloc.start()
    job()
    peak_mb = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return statistics.median(times), peak_mb


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per job (default 3)")
    args = parser.parse_args()
    cases = {"ISO-like, ±1 nm jitter": iso_like(1e-6),
             "ISO-like, ±0.01 µm jitter": iso_like(1e-5),
             "single pass, 10^5 uneven positions": single_pass()}
    diagnose(cases["ISO-like, ±1 nm jitter"], LEAD)  # warm imports
    print(f"{'case':36s} {'job':9s} {'time (s)':>9s} {'/ 5 s':>6s} {'peak MB':>8s} "
          f"{'/ 500 MB':>8s}")
    with tempfile.TemporaryDirectory() as folder:
        for label, case in cases.items():
            model = fit(LEAD, case).model
            jobs = {"diagnose": lambda case=case, model=model: diagnose(case, model),
                    "report": lambda case=case, model=model: write_report(
                        case, model, CATALOG, Path(folder) / "report.html")}
            for job_name, job in jobs.items():
                seconds, peak_mb = measure(job, args.repeats)
                print(f"{label:36s} {job_name:9s} {seconds:9.2f} {seconds / TIME_TARGET_S:6.2f} "
                      f"{peak_mb:8.0f} {peak_mb / MEMORY_TARGET_MB:8.2f}")
    print(f"({cases['ISO-like, ±1 nm jitter'].positioning.size} samples each; verdict on the "
          f"first: {diagnose(cases['ISO-like, ±1 nm jitter'], LEAD).verdict}; peak resident "
          f"memory of this whole process, imports and all cases included: "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB)")


if __name__ == "__main__":
    main()
