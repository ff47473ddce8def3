"""Many co-simulations of one scenario: ``feedaxis sweep`` and :func:`sweep`.

A sweep runs a scenario of a kind of measurement (:func:`feedaxis.kinds.scenarios`:
``iso230``, ``thermal``, ``tracking``) once per trial, each trial with its own FMU parameter values (:mod:`.sweep_specs`: ``--vary``
specs, a fitted model's covariance), and keeps each trial's figures and curve with its
inputs in one table (:mod:`pyarrow`, written as Parquet).

Where the trials run changes nothing in the table: in-process (``workers=0``), on a local
Dask cluster (``workers=N``) or on any Dask cluster (``scheduler=ADDRESS`` or ``client=``).
Trial k's values depend only on the seed and k and are drawn here, before any trial runs;
each Dask worker receives the FMUs once (as bytes: the same files everywhere, nothing
pickles an FMU), loads them once per thread into a :class:`~.master.Master` whose
instances the FMU host layer resets between trials, and runs batches of trials. The table
is sorted by trial, so it is the same bit for bit whatever the number of workers.

With an output folder the finished trials are saved in ``OUT/.partial/`` as they arrive;
Ctrl-C writes the outputs of the trials finished so far and keeps the rest for
``resume=True``, which runs only the trials still missing.
"""
from __future__ import annotations

import hashlib
import io
import json
import logging
import math
import os
import shutil
import signal
import tempfile
import threading
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, is_dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .. import __version__
from ..errors import InputError, ParameterError, json_safe
from ..kinds import scenarios as registered_scenarios
from ..output import write_atomically
from .master import FmuStepError, Master, _StopFlag
from .physics_check import check_parameters, fmu_variables
from .sweep_specs import design as make_design, model_draws

PARTIAL = ".partial"
TRIALS_FILE = "trials.parquet"
TASK_S = 2.0          # a Dask task's target duration (s): batches grow to it
MAX_BATCH = 256
FLUSH_S = 10.0        # finished trials reach OUT/.partial at least this often (s)
POLL_S = 0.02         # how often the client looks for finished Dask tasks (s)
# The local cluster's HTTP server on a free port: its default, 8787, is taken by any other
# cluster running (a second sweep), and Dask then warns on the user's terminal.
SCHEDULER_HTTP_PORT = ":0"


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C: the finished trials are kept; ``message`` says how many and how to resume."""

    def __init__(self, message):
        super().__init__(message)
        self.message = message


class TrialResult(NamedTuple):
    """One trial's outcome: its figures in the scenario's order, its curve (``series``, y
    values) and, when the FMUs refused its values, why (``error``; figures then empty)."""

    trial: int
    figures: tuple
    series: np.ndarray
    error: str | None


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


@dataclass
class Plan:
    """A sweep, checked and ready: what runs and what each trial takes."""

    scenario: str
    options: dict
    system: object
    fmu_paths: dict
    design: object
    draws: object = None
    axis: object = None
    set_items: tuple = ()
    model_path: str | None = None

    @property
    def trials(self):
        return self.design.trials

    @property
    def input_names(self):
        return self.design.names + (self.draws.keys if self.draws else ())

    def inputs(self, trial):
        """({input name: value}, {component: {parameter: value}}, redraws) of a trial."""
        values = self.design.values(trial)
        overrides, redraws = {}, 0
        if self.draws is not None:
            drawn, redraws = self.draws.values(trial)
            model = self.draws.model_at(drawn)
            for effect in model.effects:
                for fmu, fmu_values in effect.fmu_parameters(self.axis,
                                                             model.values[effect.name]).items():
                    overrides.setdefault(fmu, {}).update(fmu_values)
            values.update(drawn)
        for name in self.design.names:
            component, parameter = name.split(".", 1)
            overrides.setdefault(component, {})[parameter] = values[name]
        return values, overrides, redraws

    def identity(self, fmu_digest):
        """The plan as JSON-ready data: two sweeps with equal identities give equal tables."""
        return json_safe({
            "feedaxis": __version__, "scenario": self.scenario,
            "options": _plain(scenario_named(self.scenario).with_defaults(self.options)),
            "vary": [s.text for s in self.design.specs],
            "seed": self.design.seed, "trials": self.trials,
            "from_model": self.model_path, "held": dict(self.draws.held) if self.draws else {},
            "set": list(self.set_items), "macro_step_s": self.system.macro_step_s,
            "components": {c.name: {"step_s": c.step_s, "parameters": c.parameters}
                           for c in self.system.components},
            "fmus": fmu_digest})


def scenario_named(name):
    """The registered scenario ``name`` (:func:`feedaxis.kinds.scenarios`); InputError
    naming the known ones otherwise."""
    known = registered_scenarios()
    if name not in known:
        raise InputError(f"unknown scenario; scenarios: {', '.join(known)}",
                         parameter=f"scenario {name}")
    return known[name]


def _plain(value):
    """Options as JSON-ready data (a duty as its segments)."""
    if is_dataclass(value):
        return _plain(asdict(value))
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


class _OptionsChecked(Exception):
    """Raised by :class:`_DryMaster` once a scenario has checked its options."""


class _DryMaster:
    """A stand-in Master that stops a scenario where it would start simulating."""

    def __init__(self, system):
        self.system = system

    def run(self, *args, **kwargs):
        raise _OptionsChecked


def check_plan(plan):
    """Refuse, before any trial runs, a sweep whose options, specs or drawn values the
    scenario or the FMUs would refuse (:class:`InputError` naming the option or spec)."""
    try:
        scenario_named(plan.scenario).run(_DryMaster(plan.system), **plan.options)
    except _OptionsChecked:
        pass
    variables = fmu_variables(plan.system, plan.fmu_paths)
    check_parameters(plan.system, plan.fmu_paths, variables)
    for spec in plan.design.specs:
        for name, (low, high) in zip(spec.names, spec.support()):
            _check_within(name, low, high, variables, spec.option, "the spec's range")
    lowest, highest = _drawn_extremes(plan)
    for name, option in _options_of(plan).items():
        _check_within(name, lowest[name], highest[name], variables, option, "drawn values")
    for values in (lowest, highest):
        overrides = {}
        for name, value in values.items():
            component, parameter = name.split(".", 1)
            overrides.setdefault(component, {})[parameter] = value
        try:
            check_parameters(plan.system.with_parameters(overrides), plan.fmu_paths,
                             variables)
        except ParameterError as error:
            raise InputError(f"at the extremes of the drawn values: {error.message}",
                             parameter=_options_of(plan).get(error.parameter, error.parameter))\
                from None


def _options_of(plan):
    """{Component.parameter: the option that varies it} over every varied FMU parameter."""
    options = {name: spec.option for spec in plan.design.specs for name in spec.names}
    if plan.draws is not None:
        for fmu, values in plan.inputs(0)[1].items():
            for parameter in values:
                options.setdefault(f"{fmu}.{parameter}", "--from-model")
    return options


def _drawn_extremes(plan):
    """({Component.parameter: lowest}, {...: highest}) over every trial's FMU values."""
    lowest, highest = {}, {}
    for trial in range(plan.trials):
        for component, values in plan.inputs(trial)[1].items():
            for parameter, value in values.items():
                name = f"{component}.{parameter}"
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    continue
                lowest[name] = min(lowest.get(name, value), value)
                highest[name] = max(highest.get(name, value), value)
    return lowest, highest


def _check_within(name, low, high, variables, option, what):
    component, parameter = name.split(".", 1)
    if component not in variables:
        raise InputError(f"no component {component}; components: {', '.join(variables)}",
                         parameter=option)
    declared = variables[component].get(parameter)
    if declared is None or declared.causality != "parameter" or declared.type != "Real":
        known = sorted(n for n, v in variables[component].items()
                       if v.causality == "parameter" and v.type == "Real")
        raise InputError(f"{component} has no Real parameter {parameter}; its Real "
                         f"parameters: {', '.join(known)}", parameter=option)
    if declared.min is not None and -math.inf < low < float(declared.min):
        raise InputError(f"{what} reach {low:g}, below {name}'s minimum {declared.min} "
                         "(the FMU's bound)", parameter=option)
    if declared.max is not None and math.inf > high > float(declared.max):
        raise InputError(f"{what} reach {high:g}, above {name}'s maximum {declared.max} "
                         "(the FMU's bound)", parameter=option)


def make_plan(scenario, vary=(), trials=None, seed=0, from_model=None, axis=None,
              hold_undetermined=False, step_ms=1.0, thermal_step_s=None, model=None,
              set_items=(), effects=None, fmus=None, **options):
    """Build and check the :class:`Plan` of a sweep (arguments as :func:`sweep`)."""
    from .fmu_cache import fmu_paths
    from .system import axis_from_options

    scenario_named(scenario)
    if from_model and model:
        raise InputError("give the model to draw from (--from-model) or a fixed one (--model),"
                         " not both", parameter="--model")
    if from_model and not axis:
        raise InputError("needs --axis (the axis.toml or case folder it was fitted on): the "
                         "FMU parameters depend on the axis", parameter="--from-model")
    if not vary and not from_model:
        raise InputError("nothing varies: give --vary NAME=SPEC or --from-model M.toml",
                         parameter="--vary")
    system = axis_from_options(step_ms, thermal_step_s, from_model or model, axis, set_items,
                               effects)
    draws, axis_table = None, None
    if from_model:
        from ..case import read_axis
        from ..effects import CATALOG, load_model

        axis_path = Path(axis)
        axis_table = read_axis(axis_path / "axis.toml" if axis_path.is_dir() else axis_path)
        draws = model_draws(load_model(from_model, CATALOG if effects is None else effects),
                            seed, hold_undetermined)
    plan = Plan(scenario, options, system, fmu_paths(fmus),
                make_design(vary, trials, seed, drawn_elsewhere=draws is not None), draws,
                axis_table, tuple(set_items or ()), str(from_model) if from_model else None)
    _refuse_masked(plan)
    check_plan(plan)
    return plan


def _refuse_masked(plan):
    """A --vary or --set on an FMU parameter the drawn model sets would hide its draws."""
    if plan.draws is None:
        return
    drawn = {f"{fmu}.{p}" for fmu, values in plan.inputs(0)[1].items() for p in values}
    varied = {n: s.option for s in plan.design.specs for n in s.names}
    for name in sorted(drawn & set(varied)):
        raise InputError(f"{name} is drawn from --from-model; vary it there or here, not "
                         "both", parameter=varied[name])
    for item in plan.set_items:
        if item.partition("=")[0] in drawn:
            raise InputError("sets a parameter the drawn model sets: its draws would be "
                             "hidden", parameter=f"--set {item}")


def sweep(scenario, vary=(), trials=None, seed=0, out=None, *, from_model=None, axis=None,
          hold_undetermined=False, step_ms=1.0, thermal_step_s=None, model=None,
          set_items=(), effects=None, fmus=None, workers=None, scheduler=None, client=None,
          resume=False, progress=None, **options):
    """Run a scenario once per trial with varied FMU parameters; return the trial table.

    Parameters
    ----------
    scenario : str
        The name of a kind's scenario (:func:`feedaxis.kinds.scenarios`: ``iso230``,
        ``thermal``, ``tracking``); ``options`` are its run's keyword arguments
        (``targets_mm=...``, ``frequency_hz=...``; see ``run_<scenario>``).
    vary : sequence of str
        ``Component.parameter=SPEC`` items (:mod:`feedaxis.cosim.sweep_specs`).
    trials : int, optional
        Draws of the sampled specs (and of ``from_model``); grids set their own count.
    seed : int
        Trial k draws from ``SeedSequence(seed, spawn_key=(k, stream))``.
    out : path, optional
        Folder for trials.parquet, summary.json, summary.txt and report.html (must not
        exist unless ``resume``).
    from_model, axis : path, optional
        A fitted model with its ``[fit]`` table, and the axis.toml or case it was fitted
        on: its parameters are drawn from the fit's covariance in every trial.
    hold_undetermined : bool
        Hold the parameters the fit could not determine at their fitted values (else such
        a model is refused).
    step_ms, thermal_step_s, model, set_items, effects, fmus
        The axis, as ``feedaxis simulate`` takes it (``--step-ms``, ``--model``, ``--set``
        ...).
    workers : int, optional
        0: run in this process; N: a local Dask cluster of N processes; None: as many as
        the machine has cores. Ignored with ``scheduler`` or ``client``.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``).
    client : distributed.Client, optional
        An open Dask client to run on.
    resume : bool
        Run only the trials an interrupted sweep into ``out`` has not finished.
    progress : callable, optional
        ``progress(finished, total)`` after every finished trial.

    Returns
    -------
    pyarrow.Table
        One row per finished trial, sorted: ``trial``, the varied inputs, the scenario's
        figures, ``series`` (the scenario's curve), ``error`` (null, or why the FMUs refused
        the trial's values); the plan in the schema metadata (``feedaxis.sweep``).

    Raises
    ------
    SweepInterrupted
        On Ctrl-C, after writing the outputs of the finished trials.
    """
    plan = make_plan(scenario, vary, trials, seed, from_model, axis, hold_undetermined,
                     step_ms, thermal_step_s, model, set_items, effects, fmus, **options)
    files, digest = fmu_files(plan.fmu_paths)
    identity = plan.identity(digest)
    store = Store(out, identity, resume) if out is not None else None
    collected = store.load() if store else Collected()
    remaining = [k for k in range(plan.trials) if k not in collected.results]
    job = Job(plan.scenario, plan.options, plan.system, files, digest)
    try:
        _execute(plan, job, remaining, collected, store, workers, scheduler, client, progress)
    except KeyboardInterrupt:
        table = finish(plan, identity, collected, store)
        where = f" in {out}; run the same command with --resume for the rest" if store else ""
        raise SweepInterrupted(f"interrupted: {table.num_rows} of {plan.trials} trials "
                               f"kept{where}") from None
    return finish(plan, identity, collected, store)


@dataclass
class Collected:
    """The finished trials ({trial: TrialResult}) and the axis of their curve."""

    results: dict = field(default_factory=dict)
    series_axis: dict | None = None

    def add(self, results, series_axis):
        for result in results:
            self.results[result.trial] = result
        self.series_axis = self.series_axis or series_axis


def _execute(plan, job, remaining, collected, store, workers, scheduler, client, progress):
    """Run the ``remaining`` trials into ``collected`` (and ``store``) where asked."""
    def finished(batch_results, series_axis):
        collected.add(batch_results, series_axis)
        if store:
            store.add(batch_results, series_axis)
        if progress:
            progress(len(collected.results), plan.trials)

    if not remaining:
        return
    try:
        if client is None and scheduler is None and workers == 0:
            _run_here(plan, job, remaining, finished)
        else:
            _run_on_dask(plan, job, remaining, finished, workers, scheduler, client)
    finally:
        if store:
            store.flush()


def _run_here(plan, job, remaining, finished):
    runner = TrialRunner(job, plan.fmu_paths)
    try:
        for trial in remaining:
            result = runner.run(trial, plan.inputs(trial)[1])
            finished([result], runner.series_axis)
    finally:
        runner.close()


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
        with _ctrl_c_left_to_this_process():
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
def _ctrl_c_left_to_this_process():
    """Within: processes started ignore Ctrl-C (SIGINT ignored is inherited), so a Ctrl-C
    in the terminal stops this process, which keeps the finished trials and closes the
    cluster, instead of killing the local workers under it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


class Store:
    """The output folder of a sweep: finished trials saved as they arrive, outputs at the end.

    ``OUT/.partial/plan.json`` holds the plan's identity, ``OUT/.partial/part-N.parquet``
    the finished trials; the outputs are ``trials.parquet``, ``summary.json``,
    ``summary.txt`` and ``report.html``.
    """

    def __init__(self, out, identity, resume):
        self.out, self.identity = Path(out), identity
        self.partial = self.out / PARTIAL
        self.pending, self.series_axis, self.flushed_at = [], None, time.monotonic()
        self.parts = 0
        if resume:
            self._check_resumable()
        else:
            if self.out.exists():
                raise InputError("already exists; choose a new folder, or add --resume to "
                                 "finish an interrupted sweep there", path=self.out)
            self.partial.mkdir(parents=True)
            write_atomically(self.partial / "plan.json", json.dumps(identity, indent=1))

    def _check_resumable(self):
        plan_path = self.partial / "plan.json"
        if not plan_path.exists():
            raise InputError("holds no interrupted sweep to resume (no .partial/plan.json)",
                             path=self.out)
        saved = json.loads(plan_path.read_text())
        differ = sorted(k for k in set(saved) | set(self.identity)
                        if saved.get(k) != self.identity.get(k))
        if differ:
            raise InputError(f"holds a different sweep; it differs in {', '.join(differ)}: "
                             "resume with the command that started it", path=self.out)
        self.parts = len(list(self.partial.glob("part-*.parquet")))

    def load(self):
        """The :class:`Collected` trials saved so far."""
        import pyarrow.parquet as pq

        collected = Collected()
        for path in sorted(self.partial.glob("part-*.parquet")):
            table = pq.read_table(path)
            axis = (table.schema.metadata or {}).get(b"feedaxis.series")
            collected.add([TrialResult(row["trial"],
                                       tuple(zip(row["figure_names"], row["figure_values"])),
                                       np.array(row["series"], dtype=float), row["error"])
                           for row in table.to_pylist()], axis and json.loads(axis))
        self.series_axis = collected.series_axis
        return collected

    def add(self, results, series_axis):
        """Keep ``results``; save them when the last save is :data:`FLUSH_S` old."""
        self.pending += results
        self.series_axis = self.series_axis or series_axis
        if time.monotonic() - self.flushed_at >= FLUSH_S:
            self.flush()

    def flush(self):
        """Save the pending results as one more part file."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        self.flushed_at = time.monotonic()
        if not self.pending:
            return
        table = pa.table({
            "trial": pa.array([r.trial for r in self.pending], pa.int64()),
            "figure_names": pa.array([[n for n, _ in r.figures] for r in self.pending],
                                     pa.list_(pa.string())),
            "figure_values": pa.array([[v for _, v in r.figures] for r in self.pending],
                                      pa.list_(pa.float64())),
            "series": pa.array([r.series.tolist() for r in self.pending],
                               pa.list_(pa.float64())),
            "error": pa.array([r.error for r in self.pending], pa.string())})
        if self.series_axis:
            table = table.replace_schema_metadata(
                {"feedaxis.series": json.dumps(self.series_axis)})
        self.parts += 1
        write_atomically(self.partial / f"part-{self.parts:06d}.parquet", parquet_bytes(table))
        self.pending = []

    def complete(self):
        """Remove the saved parts once the outputs hold every trial."""
        shutil.rmtree(self.partial, ignore_errors=True)


def parquet_bytes(table):
    """``table`` as Parquet file bytes (one row group, zstd)."""
    import pyarrow.parquet as pq

    buffer = io.BytesIO()
    pq.write_table(table, buffer, compression="zstd", row_group_size=max(1, table.num_rows))
    return buffer.getvalue()


def finish(plan, identity, collected, store):
    """The trial table of the ``collected`` trials; with a store, also its files (the
    parts removed once every trial is in)."""
    from .sweep_summary import summarise, summary_lines

    table = trial_table(plan, identity, collected.results, collected.series_axis)
    if store is None:
        return table
    summary = summarise(table)
    write_atomically(store.out / TRIALS_FILE, parquet_bytes(table))
    write_atomically(store.out / "summary.json",
                     json.dumps(json_safe(summary), indent=1, allow_nan=False))
    write_atomically(store.out / "summary.txt", summary_lines(summary) + "\n")
    from ..report.sweep import write_sweep_report

    write_sweep_report(summary, table, store.out / "report.html")
    if table.num_rows == plan.trials:
        store.complete()
    return table


def trial_table(plan, identity, results, series_axis=None):
    """The finished trials as one :class:`pyarrow.Table`, sorted by trial (see
    :func:`sweep`); the plan and the series' axis in its metadata."""
    import pyarrow as pa

    trials = sorted(results)
    ordered = [results[k] for k in trials]
    names = _figure_names(ordered)
    columns = {"trial": pa.array(trials, pa.int64())}
    inputs = [plan.inputs(k) for k in trials]
    for name in plan.input_names:
        columns[name] = pa.array([values[name] for values, _, _ in inputs], pa.float64())
    if plan.draws is not None:
        columns["redraws"] = pa.array([redraws for _, _, redraws in inputs], pa.int64())
    for name in names:
        columns[name] = pa.array([dict(r.figures).get(name) for r in ordered], pa.float64())
    columns["series"] = pa.array([r.series.tolist() for r in ordered], pa.list_(pa.float64()))
    columns["error"] = pa.array([r.error for r in ordered], pa.string())
    metadata = {"plan": identity, "inputs": list(plan.input_names), "figures": names,
                "series": series_axis}
    table = pa.table(columns)
    return table.replace_schema_metadata(
        {"feedaxis.sweep": json.dumps(json_safe(metadata), allow_nan=False)})


def _figure_names(results):
    """Figure names in the scenario's order (that of the first trial with figures), then
    any other in alphabetical order."""
    first = next((r.figures for r in results if r.figures), ())
    names = [n for n, _ in first]
    others = sorted({n for r in results for n, _ in r.figures} - set(names))
    return names + others


def read_sweep(out):
    """The trial table of a sweep folder (``OUT/trials.parquet``)."""
    import pyarrow.parquet as pq

    path = Path(out) / TRIALS_FILE
    if not path.exists():
        raise InputError("no trials.parquet: not a sweep folder", path=out)
    return pq.read_table(path)


def sweep_metadata(table):
    """The ``feedaxis.sweep`` metadata of a trial table as a dict."""
    return json.loads(table.schema.metadata[b"feedaxis.sweep"])


def cluster_size(trial_s, trials=1_000_000, hours=1.0):
    """Worker cores needed to run ``trials`` trials of ``trial_s`` seconds each in ``hours``."""
    return math.ceil(trials * trial_s / (hours * 3600.0))
