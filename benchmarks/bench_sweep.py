"""Sweep benchmark: the cost of a trial in-process and on Dask, and what 10^6 trials need.

Run: ``python benchmarks/bench_sweep.py [--trials 32] [--repeats 5] [--duration-s 10]``
(``--smoke``: a tiny run for CI). The trial is the issue's: 10 s of tracking of the full
axis at a 1 ms macro step (``sweep tracking --vary NpidServo.friction_N=uniform(0,2)``).
In one run, with the repeats interleaved, it times per trial

- a plain loop in this process: one :class:`~feedaxis.cosim.sweep.TrialRunner` (the FMUs
  loaded once) running the trials one after another, nothing else;
- ``feedaxis.sweep`` on a local Dask cluster of one worker process, warm (a first sweep
  has loaded the FMUs there): the whole call, planning, checks, batching, the table;
- the same on a cluster of two worker processes.

It prints the medians (and ranges) of the wall seconds and of the CPU seconds per trial
(CPU: this process, which holds the local scheduler, plus every worker process, so what a
cluster pays whatever else the machine runs), the overhead of the distributed path over the
plain loop, the throughput of two workers over one, and from the one-worker CPU cost the
number of worker cores that run 10^6 such trials in one hour. The machine's load average
is printed with them: on a shared machine the wall times are only as good as it is idle.
"""
import argparse
import logging
import os
import statistics
import time

from distributed import Client, LocalCluster

from feedaxis.cosim.fmu_cache import cached_fmus
from feedaxis.cosim.sweep import (SCHEDULER_HTTP_PORT, Job, TrialRunner, cluster_size,
                                  fmu_files, make_plan, sweep)

VARY = ["NpidServo.friction_N=uniform(0,2)"]


def scenario(duration_s):
    return {"frequency_hz": 0.4, "amplitude_mm": 10.0, "duration_s": duration_s}


def plain_loop_s(runner, plan, trials):
    """(wall, CPU) seconds per trial of the plain loop."""
    started, cpu = time.perf_counter(), time.process_time()
    for trial in range(trials):
        result = runner.run(trial, plan.inputs(trial)[1])
        assert result.error is None, result.error
    return ((time.perf_counter() - started) / trials, (time.process_time() - cpu) / trials)


def dask_s(client, trials, duration_s, seed):
    """(wall, CPU) seconds per trial of a whole ``sweep`` call on ``client``; CPU of this
    process and of every worker."""
    workers_cpu = client.run(time.process_time)
    started, cpu = time.perf_counter(), time.process_time()
    table = sweep("tracking", VARY, trials=trials, seed=seed, client=client,
                  **scenario(duration_s))
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    cpu += sum(after - workers_cpu[address]
               for address, after in client.run(time.process_time).items())
    assert table.num_rows == trials and table.column("error").null_count == trials
    return wall / trials, cpu / trials


def summary(label, values):
    """(median wall, median CPU, the line printed) of [(wall, CPU)] per trial."""
    walls, cpus = [w for w, _ in values], [c for _, c in values]
    wall, cpu = statistics.median(walls), statistics.median(cpus)
    return wall, cpu, (f"{label:<32} wall {wall * 1e3:7.1f} ms/trial (range "
                       f"{min(walls) * 1e3:.0f}-{max(walls) * 1e3:.0f}), CPU "
                       f"{cpu * 1e3:7.1f} ms/trial (range {min(cpus) * 1e3:.0f}-"
                       f"{max(cpus) * 1e3:.0f}), {len(values)} runs")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=32, help="trials per timed sweep")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--duration-s", type=float, default=10.0)
    parser.add_argument("--smoke", action="store_true", help="tiny sizes (CI)")
    args = parser.parse_args(argv)
    if args.smoke:
        args.trials, args.repeats, args.duration_s = 2, 1, 1.2
    plan = make_plan("tracking", VARY, trials=args.trials, seed=0, **scenario(args.duration_s))
    files, digest = fmu_files(cached_fmus())
    runner = TrialRunner(Job("tracking", plan.options, plan.system, files, digest),
                         plan.fmu_paths)
    clusters = {n: LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                dashboard_address=SCHEDULER_HTTP_PORT,
                                silence_logs=logging.ERROR)
                for n in (1, 2)}
    clients = {n: Client(cluster) for n, cluster in clusters.items()}
    times = {"plain": [], 1: [], 2: []}
    load_before = os.getloadavg()[0]
    try:
        for n, client in clients.items():  # warm: each worker loads its FMUs once
            dask_s(client, n, args.duration_s, seed=99)
        plain_loop_s(runner, plan, 1)
        for repeat in range(args.repeats):
            times["plain"].append(plain_loop_s(runner, plan, args.trials))
            for n, client in clients.items():
                times[n].append(dask_s(client, args.trials, args.duration_s, seed=repeat))
    finally:
        runner.close()
        for item in (*clients.values(), *clusters.values()):
            item.close()
    plain, plain_cpu, line_plain = summary("plain loop in this process", times["plain"])
    one, one_cpu, line_one = summary("feedaxis.sweep, Dask, 1 worker", times[1])
    two, _, line_two = summary("feedaxis.sweep, Dask, 2 workers", times[2])
    print(f"{args.trials} trials of {args.duration_s:g} s tracking at 1 ms per timed sweep; "
          f"load average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after "
          f"({os.cpu_count()} cores)")
    print("\n".join((line_plain, line_one, line_two)))
    print(f"distributed overhead per trial (1 worker / plain loop - 1): wall "
          f"{100 * (one / plain - 1):+.1f} %, CPU {100 * (one_cpu / plain_cpu - 1):+.1f} % "
          "(target <= 10 %)")
    print(f"throughput of 2 workers / 1 worker: {one / two:.2f}x (target >= 1.7x); "
          f"2 workers / plain loop: {plain / two:.2f}x")
    print(f"10^6 such trials in one hour: {cluster_size(one_cpu)} worker cores at "
          f"{one_cpu * 1e3:.0f} CPU ms per trial ({1e6 * one_cpu / 3600:.0f} core-hours)")


if __name__ == "__main__":
    main()
