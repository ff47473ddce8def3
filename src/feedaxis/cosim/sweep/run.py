"""Where a sweep's trials run: in this process or on a Dask cluster (local, or any by its
scheduler's address), batches of trials sent to workers that keep their FMUs loaded."""
from __future__ import annotations

import hashlib
import logging
import math
import os
import shutil
import signal
import tempfile
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import InputError, ParameterError
from ..master import FmuStepError, Master, _StopFlag
from .plan import scenario_named
from .store import TrialResult

TASK_S = 2.0          # a Dask task's target duration (s): batches grow to it
MAX_BATCH = 256
POLL_S = 0.02         # how often the client looks for finished Dask tasks (s)
# What a local cluster costs before its first trial and after its last (importing Dask,
# starting the scheduler and the worker processes, each loading the FMUs, closing them):
# a 1-trial sweep took 3.5 s on a local cluster of 2 against about 1 s in process on an
# idle 2-core machine; 6.5 s measured for the cluster alone under a load of 13.
CLUSTER_START_S = 3.0
# The local cluster's HTTP server on a free port: its default, 8787, is taken by any other
# cluster running (a second sweep), and Dask then warns on the user's terminal.
SCHEDULER_HTTP_PORT = ":0"


@dataclass(frozen=True)
class Job:
    """What every worker needs, sent once: the scenario, the base system, the FMU files."""

    scenario: str
    options: dict
    system: object
    fmus: dict
    digest: str


def fmu_files(paths):
    """({FMU name: bytes}, SHA-256 over them) of the FMU files at ``paths``."""
    files = {name: Path(path).read_bytes() for name, path in sorted(paths.items())}
    digest = hashlib.sha256()
    for name, data in files.items():
        digest.update(name.encode())
        digest.update(hashlib.sha256(data).digest())
    return files, digest.hexdigest()[:16]


class TrialRunner:
    """A Master over the job's FMUs, loaded once, running trials one after another."""

    def __init__(self, job, paths=None):
        self.job = job
        self.folder = None
        if paths is None:
            self.folder = tempfile.mkdtemp(prefix="feedaxis-sweep-fmus-")
            paths = {}
            for name, data in job.fmus.items():
                paths[name] = Path(self.folder) / f"{name}.fmu"
                paths[name].write_bytes(data)
        self.master = Master(job.system, paths)
        self.scenario = scenario_named(job.scenario)
        self.series_axis = None

    def run(self, trial, overrides):
        """The :class:`TrialResult` of one trial with ``overrides`` over the system.

        Raises
        ------
        KeyboardInterrupt
            When Ctrl-C stopped the run (the trial did not finish).
        """
        try:
            run = self.scenario.run(self.master, **self.job.options, parameters=overrides)
        except (ParameterError, FmuStepError) as error:
            return TrialResult(trial, (), np.zeros(0), str(error))
        if not run.completed:
            raise KeyboardInterrupt
        series = run.series
        if self.series_axis is None:
            self.series_axis = {"x_name": series.x_name, "x": series.x.tolist(),
                                "y_name": series.y_name, "group": list(series.group)}
        return TrialResult(trial, tuple(run.figures.items()), np.asarray(series.y, float), None)

    def close(self):
        self.master.close()
        if self.folder:
            shutil.rmtree(self.folder, ignore_errors=True)


_local = threading.local()


def _runner(job):
    """This thread's :class:`TrialRunner` of ``job`` (one per thread: FMU instances are not
    shared); a runner of an earlier job is closed."""
    runner = getattr(_local, "runner", None)
    if runner is None or runner.job.digest != job.digest:
        if runner is not None:
            runner.close()
        runner = _local.runner = TrialRunner(job)
    return runner


def run_batch(job, batch):
    """Run ``batch`` ([(trial, overrides)]) on this worker; return (series axis, results,
    seconds spent)."""
    started = time.perf_counter()
    runner = _runner(job)
    results = [runner.run(trial, overrides) for trial, overrides in batch]
    return runner.series_axis, results, time.perf_counter() - started


def execute(plan, job, remaining, collected, store, workers, scheduler, client, progress,
            echo=None):
    """Run the ``remaining`` trials into ``collected`` (and ``store``) where asked: with
    ``workers`` None, in this process for as long as a local cluster would not finish
    sooner (``echo`` says so when it never would)."""
    def finished(batch_results, series_axis):
        collected.add(batch_results, series_axis)
        if store:
            store.add(batch_results, series_axis)
        if progress:
            progress(len(collected.results), plan.trials)

    if not remaining:
        return
    try:
        if client is not None or scheduler is not None or workers:
            _run_on_dask(plan, job, remaining, finished, workers, scheduler, client)
            return
        cores = 1 if workers == 0 else (os.cpu_count() or 1)
        left = _run_here(plan, job, remaining, finished, cores)
        if left:
            _run_on_dask(plan, job, left, finished, workers, scheduler, client)
        elif cores > 1 and echo:
            echo(f"ran in this process: {len(remaining)} trial(s) finish here before a local "
                 f"cluster of {cores} workers would pay for its start (about "
                 f"{CLUSTER_START_S:g} s); --workers N runs on one anyway")
    finally:
        if store:
            store.flush()


def _run_here(plan, job, remaining, finished, cores=1):
    """Run trials in this process while that finishes sooner than a local cluster of
    ``cores`` workers would (:func:`cluster_pays`, judged after every trial from their
    mean time); return the trials left for the cluster."""
    runner = TrialRunner(job, plan.fmu_paths)
    started = time.perf_counter()
    try:
        for done, trial in enumerate(remaining):
            trial_s = (time.perf_counter() - started) / max(done, 1)
            if done and cluster_pays(len(remaining) - done, trial_s, cores):
                return remaining[done:]
            result = runner.run(trial, plan.inputs(trial)[1])
            finished([result], runner.series_axis)
    finally:
        runner.close()
    return []


def cluster_pays(trials, trial_s, cores):
    """True when ``trials`` of ``trial_s`` each finish sooner on a local cluster of
    ``cores`` workers, its start (:data:`CLUSTER_START_S`) included, than here."""
    return cores > 1 and CLUSTER_START_S + trials * trial_s / cores < trials * trial_s


def _run_on_dask(plan, job, remaining, finished, workers, scheduler, client):
    """Batches of trials on a Dask cluster; at most two batches per worker thread wait."""
    from distributed import as_completed

    with _dask_client(workers, scheduler, client) as dask:
        job_future = dask.scatter(job, broadcast=True, hash=False)
        slots = 2 * max(1, sum(dask.nthreads().values()))
        queue, batch_size = list(reversed(remaining)), 1
        running = as_completed()

        def submit():
            # guided self-scheduling: no batch takes more than its share of what is left,
            # so the last batches finish together instead of one worker running alone
            share = -(-len(queue) // slots)
            batch = [queue.pop() for _ in range(min(batch_size, share))]
            inputs = [(trial, plan.inputs(trial)[1]) for trial in batch]
            running.add(dask.submit(run_batch, job_future, inputs, pure=False))

        for _ in range(min(slots, len(queue))):
            submit()
        try:
            with _StopFlag() as stop:  # Ctrl-C must not land inside Dask's own calls
                while not running.is_empty():
                    if stop.requested:
                        raise KeyboardInterrupt
                    done = running.next_batch(block=False)
                    if not done:
                        time.sleep(POLL_S)
                    for future in done:
                        series_axis, batch_results, seconds = future.result()
                        finished(batch_results, series_axis)
                        batch_size = min(MAX_BATCH, max(1, round(
                            TASK_S * len(batch_results) / max(seconds, 1e-9))))
                        if queue:
                            submit()
        finally:
            for future in list(running.futures):
                future.cancel()


class _dask_client:
    """The Dask client to run on: the caller's, one connected to ``scheduler``, or a new
    local cluster of ``workers`` processes (one thread each) closed on exit."""

    def __init__(self, workers, scheduler, client):
        self.workers, self.scheduler, self.client = workers, scheduler, client
        self.owned = []

    def __enter__(self):
        from distributed import Client, LocalCluster

        if self.client is not None:
            return self.client
        if self.scheduler is not None:
            try:
                client = Client(self.scheduler, timeout="20s")
            except (OSError, TimeoutError) as error:
                raise InputError(f"no Dask scheduler answers there: {error}",
                                 parameter=f"--scheduler {self.scheduler}") from None
            self.owned.append(client)
            return client
        count = self.workers if self.workers is not None else (os.cpu_count() or 1)
        if not (isinstance(count, int) and count >= 1):
            raise InputError(f"must be a whole number >= 0, got {count}", parameter="--workers")
        with _ctrl_c_left_to_this_process(), _forked_workers():
            cluster = LocalCluster(n_workers=count, threads_per_worker=1, processes=True,
                                   dashboard_address=SCHEDULER_HTTP_PORT,
                                   silence_logs=logging.ERROR)
        client = Client(cluster)
        self.owned += [client, cluster]
        return client

    def __exit__(self, *exc):
        for owned in self.owned:
            owned.close()


@contextmanager
def _forked_workers():
    """Within: local workers are forked from one server process that imported Dask and
    what a trial needs once (multiprocessing's forkserver), instead of each starting a
    fresh Python that imports them again (spawn, Dask's default). A cluster of 2 came up
    in 2.2-2.4 s against 3.3-3.6 s and closed in 0.05 s against 1 s (under a load of 11
    on 2 cores). Where there is no forkserver (Windows), Dask's default."""
    import multiprocessing

    import dask

    if "forkserver" not in multiprocessing.get_all_start_methods():
        yield
        return
    multiprocessing.set_forkserver_preload(["distributed", __name__])
    with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}):
        yield


@contextmanager
def _ctrl_c_left_to_this_process():
    """Within: processes started ignore Ctrl-C and SIGHUP (an ignored signal is inherited),
    so a Ctrl-C in the terminal, or the terminal closing, stops this process, which keeps
    the finished trials and closes the cluster, instead of killing the local workers under
    it. SIGTERM stays: the cluster stops its workers with it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    ignored = [getattr(signal, name) for name in ("SIGINT", "SIGHUP") if hasattr(signal, name)]
    previous = {signum: signal.signal(signum, signal.SIG_IGN) for signum in ignored}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def cluster_size(trial_s, trials=1_000_000, hours=1.0):
    """Worker cores needed to run ``trials`` trials of ``trial_s`` seconds each in ``hours``."""
    return math.ceil(trials * trial_s / (hours * 3600.0))
