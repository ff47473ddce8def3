"""Many co-simulations of one scenario: ``feedaxis sweep`` and :func:`sweep`.

A sweep runs a scenario of a kind of measurement (:func:`feedaxis.kinds.scenarios`:
``iso230``, ``thermal``, ``tracking``) once per trial, each trial with its own FMU
parameter values (:mod:`.specs`: ``--vary`` specs, a fitted model's covariance), and keeps
each trial's figures and curve with its inputs in one table (:mod:`pyarrow`, written as
Parquet). The parts: :mod:`.plan` (what runs, checked first), :mod:`.run` (in this
process or on Dask), :mod:`.store` (the output folder and the trial table),
:mod:`.specs` (the ``--vary`` specs and model draws), :mod:`.summary` (quantiles,
sensitivities, bands).

Where the trials run changes nothing in the table: in-process (``workers=0``), on a local
Dask cluster (``workers=N``) or on any Dask cluster (``scheduler=ADDRESS`` or ``client=``).
Trial k's values depend only on the seed and k and are drawn here, before any trial runs;
each Dask worker receives the FMUs once (as bytes: the same files everywhere, nothing
pickles an FMU), loads them once per thread into a :class:`~feedaxis.cosim.master.Master`
whose instances the FMU host layer resets between trials, and runs batches of trials. The
table is sorted by trial, so it is the same bit for bit whatever the number of workers.

With an output folder the finished trials are saved in ``OUT/.partial/`` as they arrive;
Ctrl-C writes the outputs of the trials finished so far and keeps the rest for
``resume=True``, which runs only the trials still missing.
"""
from __future__ import annotations

from .plan import Plan, make_plan
from .run import (SCHEDULER_HTTP_PORT, Job, TrialRunner, cluster_size, execute, fmu_files,
                  run_batch)
from .store import (Collected, Store, TrialResult, finish, parquet_bytes, read_sweep,
                    sweep_metadata, trial_table)

__all__ = ["SCHEDULER_HTTP_PORT", "Collected", "Job", "Plan", "Store", "SweepInterrupted",
           "TrialResult", "TrialRunner", "cluster_size", "fmu_files", "make_plan",
           "parquet_bytes", "read_sweep", "run_batch", "sweep", "sweep_metadata",
           "trial_table"]


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C: the finished trials are kept; ``message`` says how many and how to resume."""

    def __init__(self, message):
        super().__init__(message)
        self.message = message


def sweep(scenario, vary=(), trials=None, seed=0, out=None, *, from_model=None, axis=None,
          hold_undetermined=False, step_ms=1.0, thermal_step_s=None, model=None,
          set_items=(), effects=None, fmus=None, workers=None, scheduler=None, client=None,
          resume=False, progress=None, echo=None, **options):
    """Run a scenario once per trial with varied FMU parameters; return the trial table.

    Parameters
    ----------
    scenario : str
        The name of a kind's scenario (:func:`feedaxis.kinds.scenarios`: ``iso230``,
        ``thermal``, ``tracking``); ``options`` are its run's keyword arguments
        (``targets_mm=...``, ``frequency_hz=...``; see ``run_<scenario>``).
    vary : sequence of str
        ``Component.parameter=SPEC`` items (:mod:`feedaxis.cosim.sweep.specs`).
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
        0: run in this process; N: a local Dask cluster of N processes; None: in this
        process while the trials left would not finish sooner on a local cluster of as
        many processes as the machine has cores (its start included, judged from the
        trials' mean time), then on that cluster. Ignored with ``scheduler`` or ``client``.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``).
    client : distributed.Client, optional
        An open Dask client to run on.
    resume : bool
        Run only the trials an interrupted sweep into ``out`` has not finished.
    progress : callable, optional
        ``progress(finished, total)`` after every finished trial.
    echo : callable, optional
        Given a line of text when the default ``workers`` ran every trial in this process.

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
        execute(plan, job, remaining, collected, store, workers, scheduler, client, progress,
                echo)
    except KeyboardInterrupt:
        table = finish(plan, identity, collected, store)
        where = f" in {out}; run the same command with --resume for the rest" if store else ""
        raise SweepInterrupted(f"interrupted: {table.num_rows} of {plan.trials} trials "
                               f"kept{where}") from None
    return finish(plan, identity, collected, store)
