"""What every simulated scenario shares: the :class:`Scenario` a kind of measurement
declares (its ``scenarios`` part, read through :func:`feedaxis.kinds.scenarios`), the
:class:`ScenarioRun` it returns, the measurement noise and the case folder it is written as.

A scenario runs in memory (``run(master, **keywords, parameters=, progress=)`` ->
:class:`ScenarioRun`: the case's columns by file, the figures, the curve a sweep bands);
:func:`write_run` writes it as a case folder (docs/case-format.md). ``feedaxis simulate NAME``
and ``feedaxis sweep NAME`` read the scenario's command-line options and its terminal line
from the same object, so a scenario is defined once, in its kind's scenario module
(:mod:`.positioning`, :mod:`.tracking`). Ctrl-C stops a run cleanly; what was computed is
written as a (shorter) case and :class:`ScenarioInterrupted` says where.
"""
from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ...case import CaseError, range_problem, read_case, write_case
from ...errors import InputError, ParameterError
from ...fmu_map import AXIS_KEYS, SERVO_KEYS, servo_from_fmu
from ...kinds import kinds
from ...physics.checks import require_positive
from ..physics_check import start_value

MAX_MACRO_STEPS = 1e9  # 11.6 days of axis time at 1 ms: days of computing


@dataclass(frozen=True)
class Scenario:
    """A simulated test of one kind of measurement: ``feedaxis simulate NAME`` and
    ``feedaxis sweep NAME``.

    ``run(master, **keywords, parameters=None, progress=None)`` -> :class:`ScenarioRun`;
    ``options(parser)`` adds its command-line options, ``arguments(args)`` turns them into
    ``run``'s keywords, ``line(args, summary)`` is the terminal's line of ``simulate``;
    ``help`` and ``description`` are its ``--help``. A scenario on another system than the
    one axis of the axis options gives ``system(args)`` (the circular test's machine of two
    axes), and one whose case describes its axis itself ``write(out, master, run, noise)``
    (default :func:`write_run`); ``sweeps`` False keeps it out of ``feedaxis sweep``.
    """

    name: str
    run: Callable
    options: Callable
    arguments: Callable
    line: Callable
    help: str = ""
    description: str = ""
    system: Callable | None = None
    write: Callable | None = None
    sweeps: bool = True

    def with_defaults(self, keywords):
        """``keywords`` of :attr:`run` with its defaults filled in, so keywords given and
        keywords left at their default describe the same run (a sweep's plan)."""
        bound = inspect.signature(self.run).bind_partial(**keywords)
        bound.apply_defaults()
        return {k: v for k, v in bound.arguments.items()
                if k not in ("master", "parameters", "progress")}

    def simulate(self, out, master, parameters=None, progress=None, noise=None, **keywords):
        """Run the scenario and write it as the case folder ``out`` (:func:`write_run`);
        return its summary."""
        run = self.run(master, **keywords, parameters=parameters, progress=progress)
        return (self.write or write_run)(out, master, run, noise)


@dataclass(frozen=True)
class Series:
    """The curve of one run that a sweep gives bands of: ``y`` against ``x``, one line per
    value of ``group`` (approach direction, target, ...)."""

    x_name: str
    x: np.ndarray
    y_name: str
    y: np.ndarray
    group: tuple


@dataclass(frozen=True)
class ScenarioRun:
    """One scenario run in memory.

    ``tables`` are the case's columns by file (``duty`` and each kind's), ``figures`` the
    scenario's figures (µm or mm, named with their unit), ``summary`` what ``feedaxis
    simulate`` reports, ``parameters`` the overrides it ran with; ``with_servo``: axis.toml
    gets the ``[servo]`` table. ``stopped`` is empty for a complete run; after Ctrl-C it
    says what the tables hold (they hold what was reached), ending where the folder is
    named.
    """

    name: str
    parameters: dict
    tables: dict
    figures: dict
    series: Series
    summary: dict
    stopped: str = ""
    with_servo: bool = False

    @property
    def completed(self):
        """False after Ctrl-C."""
        return not self.stopped


class ScenarioInterrupted(KeyboardInterrupt):
    """Ctrl-C: the partial result was written; ``message`` says where and how much."""

    def __init__(self, message):
        super().__init__(message)
        self.message = message


@dataclass(frozen=True)
class MeasurementNoise:
    """White Gaussian noise added to what a case records as measured (each kind's
    ``measured_column``), standard deviation ``sigma_um``, drawn by
    ``numpy.random.default_rng(seed)``: the simulated axis measured by an instrument."""

    sigma_um: float
    seed: int = 0

    def __post_init__(self):
        if not (math.isfinite(self.sigma_um) and self.sigma_um >= 0):
            raise ParameterError(f"must be a finite number >= 0 (µm), got {self.sigma_um}",
                                 parameter="--noise-um")

    def measured(self, tables):
        """``tables`` with the noise added to their measured column."""
        rng = np.random.default_rng(self.seed)
        noisy = dict(tables)
        for table, kind in kinds().items():
            column, mm_per_um = kind.measured_column
            if table in tables:
                measured = np.asarray(tables[table][column], dtype=float)
                noisy[table] = {**tables[table], column: measured
                                + mm_per_um * rng.normal(0.0, self.sigma_um, measured.size)}
        return noisy


def check_axis_ranges(system):
    """Refuse, before anything is simulated, an FMU parameter the simulated case's axis.toml
    would hold (:data:`~feedaxis.fmu_map.AXIS_KEYS`) beyond any physical axis: the case
    format's ranges, naming ``Component.parameter``."""
    for table in AXIS_KEYS.values():
        for component in system.components:
            for key in table.get(component.fmu, ()):
                value = component.parameters.get(key)
                if isinstance(value, (int, float)) and not isinstance(value, bool):
                    problem = range_problem(key, value)
                    if problem:
                        raise InputError(f"{value:g} {problem} (axis.toml of the simulated "
                                         "case)", parameter=f"{component.name}.{key}")


def _readable(staged):
    """Refuse a simulated case the case reader would refuse (parameter values beyond any
    physical axis, such as --set GeometricError.offset_um=1e300), naming the file, row and
    column it would break, before it is published."""
    try:
        read_case(staged)
    except CaseError as error:
        where = ", ".join([error.path.name] + ([f"row {error.row}"] if error.row else [])
                          + ([f"column '{error.column}'"] if error.column else []))
        raise InputError(f"the simulated case would not be readable ({where}: "
                         f"{error.message}): a parameter value (--set, --model) beyond what "
                         "a case can hold (docs/bad-input.md)", parameter="--set") from None


def write_run(out, master, run, noise=None, axis=None):
    """Write ``run`` as the case folder ``out``, its measured column with ``noise`` (a
    :class:`MeasurementNoise`) when given, its axis.toml ``axis`` (default
    :func:`axis_values` of the run); return its summary with the folder. The summary's
    figures are the simulated axis's, before the noise.

    Raises
    ------
    ScenarioInterrupted
        After writing an interrupted run, saying what it holds.
    """
    tables = noise.measured(run.tables) if noise else run.tables
    if axis is None:
        axis = axis_values(master, run.parameters, run.name, with_servo=run.with_servo)
    write_case(out, axis, **tables, check=_readable)
    summary = {"case": str(out), **run.summary}
    if noise:
        summary["noise"] = {"sigma_um": noise.sigma_um, "seed": noise.seed}
    if not run.completed:
        raise ScenarioInterrupted(f"{run.stopped} {out}")
    return summary


def axis_values(master, parameters, name, with_servo=False):
    """axis.toml content from the co-simulated axis's effective parameter values; with
    ``with_servo`` the ``[servo]`` table too (the controller as set in NpidServo, not its
    plant or friction: those are what a fit of the tracking case identifies)."""
    system = master.system.with_parameters(parameters or {})

    def values(component, keys):
        c = system.component(component)
        variables = master.loaded[c.fmu].variables
        return {k: c.parameters[k] if k in c.parameters else start_value(variables[k]) for k in keys}

    axis = {"name": name, **{table: axis_table(table, values) for table in AXIS_KEYS}}
    if with_servo:
        axis["servo"] = servo_from_fmu(values("NpidServo", [*SERVO_KEYS.values(), "nonlinear"]))
    return axis


def axis_table(table, values):
    """axis.toml ``[table]`` from the FMUs that take its keys (:data:`AXIS_KEYS`); a key
    several FMUs take must have one value in all of them."""
    found = {}
    for fmu, keys in AXIS_KEYS[table].items():
        for key, value in values(fmu, keys).items():
            found.setdefault(key, {})[fmu] = value
    differ = {key: by_fmu for key, by_fmu in found.items() if len(set(by_fmu.values())) > 1}
    if differ:
        by_fmu = next(iter(differ.values()))
        raise ParameterError(f"{' and '.join(by_fmu)} disagree on {', '.join(differ)}: one "
                             f"axis has one {table}", "--set")
    return {key: next(iter(by_fmu.values())) for key, by_fmu in found.items()}


def stop_time_s(duration_s, macro_step_s):
    """``duration_s`` rounded up to whole macro steps; refused beyond :data:`MAX_MACRO_STEPS`
    (a feed near 0 or a step near 0 would otherwise run for ever)."""
    steps = duration_s / macro_step_s
    if not steps <= MAX_MACRO_STEPS:
        raise ParameterError(f"the run would take {duration_s:.4g} s in {steps:.4g} macro steps "
                             f"of {macro_step_s:g} s, more than the {MAX_MACRO_STEPS:.0e} "
                             "feedaxis simulates; check the feed, the targets and --step-ms",
                             "duration")
    return math.ceil(steps - 1e-9) * macro_step_s


def require_positive_values(**values):
    """Refuse any of ``values`` (name=value) that is not a finite number > 0."""
    for name, value in values.items():
        require_positive(name, value)
