"""The Monte Carlo uncertainty of a positioning case: :func:`evaluate` runs the measurement
model of :mod:`.positioning` through the engine of :mod:`.engine` and gathers, per figure,
parameter and table point, the value, standard uncertainty, 95 % coverage intervals and each
input's share (:class:`Uncertainty`)."""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ..measurement.positioning import POSITIONING_FILE
from ..errors import InputError
from ..fit import fit
from ..standards import DEFAULT, STANDARDS, THERMAL, UNDEFINED, FigureSet
from ..standards.thermal import ThermalFigures, check_thermal
from . import engine
from .budget import CONTRIBUTIONS, default_budget
from .correction import OPTION, corrected_case, correction_for
from .positioning import (LINEARISATION_TOLERANCE, REPEATABILITY, PositioningMeasurement,
                          ReadingNoise)

CHUNK_VALUES = 2 ** 21  # deviations or table values at once: 16 MB, whatever the trials
CHECK_TRIALS = 4  # trials refitted to check the linearisation
REFIT_TRIALS = 200  # trials refitted when the linearisation fails its check
HISTOGRAM_VALUES = 20_000
TABLE_TRIALS = 20_000  # the table's values are summarised over the first trials only
NUMBER_KEYS = ("value", "mean", "standard_uncertainty", "coverage_interval",
               "shortest_coverage_interval")
ISO_RUNS = 5  # runs per target and direction of an ISO 230-2 test
MOMENT_NAMES = {"mean": "mean", "standard_uncertainty": "variance"}
SPECIAL_BLOCK = 10 ** 6  # a seed stream apart from the trials' for the check and refits


@dataclass
class Uncertainty:
    """The result of :func:`evaluate`: per figure, parameter and table point its value,
    Monte Carlo mean, standard uncertainty, 95 % coverage intervals and each input's share."""

    case: str
    trials: int
    seed: int
    inputs: tuple
    budget: object
    correction: object
    repeatability: str
    figures: dict
    standard: str = STANDARDS[DEFAULT].title
    parameters: dict = field(default_factory=dict)
    undetermined: dict = field(default_factory=dict)
    parameter_method: dict = field(default_factory=dict)
    table: dict | None = None
    adaptive: object = None
    notes: list = field(default_factory=list)
    moments: tuple = engine.MOMENTS  # the moments the outputs have (none without a variance)
    samples: dict = field(default_factory=dict, repr=False)

    def to_json(self):
        """Strict-JSON-ready dict (non-finite numbers are turned into null by the caller)."""
        return {"case": self.case, "method": "Monte Carlo, JCGM 101:2008", "coverage": 0.95,
                "trials": self.trials, "seed": self.seed,
                "adaptive": self.adaptive.to_json() if self.adaptive else None,
                "inputs": list(self.inputs), "repeatability": self.repeatability,
                "budget": self.budget.to_json(), "standard": self.standard,
                "corrected_to_20C": self.correction.to_json() if self.correction else None,
                "figures": self.figures, "parameters": self.parameters,
                "undetermined": self.undetermined, "parameter_method": self.parameter_method,
                "table": self.table, "notes": self.notes,
                "moments": {moment: moment in self.moments for moment in engine.MOMENTS}}


def evaluate(case, model=None, budget=None, trials=engine.DEFAULT_TRIALS, tolerance_um=None,
             seed=None, temperature=None, progress=None, standard=DEFAULT):
    """The Monte Carlo uncertainty of a positioning case.

    Parameters
    ----------
    case : Case
        With positioning.csv.
    model : Model, optional
        Refitted on the case (after the 20 °C correction); its parameters and table then
        get their uncertainty.
    budget : Budget, optional
        Default: :func:`default_budget`.
    trials : int
        Monte Carlo trials (ignored with ``tolerance_um``).
    tolerance_um : float, optional
        Run the adaptive procedure of JCGM 101 §7.9 to this numerical tolerance (µm) of
        every figure's mean, standard uncertainty and interval ends.
    seed : int, optional
        The random seed (default: fresh, reported in the result).
    temperature : "ambient" or float, optional
        Correct the case to 20 °C at this temperature (°C), with its uncertainty.
    progress : callable, optional
        ``progress(trials, planned)`` after every chunk: the trials it ran and the trials
        planned in all (None for the adaptive procedure, which ends when it stabilises).
    standard : str
        The standard whose figures get their uncertainty (``all``: every defined one).

    Returns
    -------
    Uncertainty
    """
    if case.positioning is None:
        raise InputError("the uncertainty of ISO 230-2 figures needs positioning.csv",
                         path=case.folder)
    if tolerance_um is not None and not tolerance_um > 0:
        raise InputError(f"must be > 0, got {tolerance_um:g}", parameter="--tolerance-um")
    if tolerance_um is None and not trials >= engine.MIN_TRIALS:
        raise InputError(f"must be at least {engine.MIN_TRIALS} (JCGM 101 §7.2: a 95 % "
                         "interval needs many more than 1/(1 - p) = 20 trials)",
                         parameter="--trials")
    outputs = _figure_set(standard, case)
    budget = budget or default_budget()
    correction = correction_for(case, temperature) if temperature is not None else None
    case = corrected_case(case, temperature)
    fitted = (fit(model, case, kind="positioning") if model is not None and model.effects
              else None)
    measurement = PositioningMeasurement(case, budget, correction, fitted, outputs)
    inputs = measurement.inputs
    moments = (measurement.repeatability.moments if REPEATABILITY in inputs
               else engine.MOMENTS)
    if not inputs:
        raise InputError("nothing to propagate: every budget contribution is 0 and the data "
                         "carry no repeatability (one reading per target, no model)",
                         path=case.folder / POSITIONING_FILE)
    seed = int(np.random.SeedSequence().entropy if seed is None else seed)
    if progress:
        planned = None if tolerance_um else trials + len(inputs) * min(
            trials, engine.CONTRIBUTION_TRIALS)
        progress = partial(_report_progress, progress, planned)
    chunk = max(1, CHUNK_VALUES // max(case.positioning.size, measurement.table.size))
    adaptive = None
    keep = {"table_um": TABLE_TRIALS}
    if tolerance_um is None:
        values = engine.run(measurement.sample, inputs, trials, seed, chunk, progress=progress,
                            keep=keep)
    else:
        judged = list(measurement.figures())
        values, adaptive = engine.run_adaptive(measurement.sample, inputs, tolerance_um,
                                               judged, seed, chunk, progress=progress,
                                               keep=keep, moments=moments,
                                               min_blocks=engine.MIN_BLOCKS_WITHOUT_VARIANCE
                                               if len(moments) < 2 else 2)
    done = len(values[next(iter(measurement.figures()))])
    alone = engine.contributions(measurement.sample, inputs, seed, chunk,
                                 min(done, engine.CONTRIBUTION_TRIALS), progress)
    result = Uncertainty(str(case.folder), done, seed, inputs, budget, correction,
                         measurement.repeatability.source, {}, outputs.title,
                         adaptive=adaptive, notes=_notes(measurement, correction),
                         moments=moments)
    shares = engine.shares(alone)
    if "standard_uncertainty" not in moments:  # the repeatability's u² is infinite
        alone[REPEATABILITY] = {key: np.full_like(u, np.nan)
                                for key, u in alone[REPEATABILITY].items()}
        shares = {key: {name: np.full_like(u, np.nan) for name, u in by_input.items()}
                  for key, by_input in shares.items()}
    result.figures = _figures(outputs.names(), measurement.figures(), values, alone, shares,
                              moments)
    result.samples = {key: values[key][:HISTOGRAM_VALUES] for key in result.figures}
    if measurement.parameters:
        _parameters(result, measurement, values, alone, shares, seed, chunk, progress)
    if measurement.table.included:
        result.table = _table(measurement.table, values["table_um"], alone, moments)
    return result


def _report_progress(progress, planned, trials):
    progress(trials, planned)


def _interval_entry(value, summary, index=(), moments=engine.MOMENTS):
    """The numbers of one output element: value, mean, u (None where the output has no
    such moment) and the two intervals."""
    return {"mean": _moment(summary, "mean", index, moments),
            "standard_uncertainty": _moment(summary, "standard_uncertainty", index, moments),
            "coverage_interval": [float(v) for v in summary.symmetric[(slice(None),) + index]],
            "shortest_coverage_interval": [float(v)
                                           for v in summary.shortest[(slice(None),) + index]],
            **({} if value is None else {"value": float(value)})}


def _moment(summary, name, index, moments):
    """The ``name`` moment of ``summary`` at ``index``, or None where it does not exist."""
    return float(getattr(summary, name)[index]) if name in moments else None


def _optional(value):
    """``value`` as a float, None for NaN (a share or u that does not exist)."""
    return None if np.isnan(value) else float(value)


def _with_unit(entry, unit):
    """``entry`` with its numbers' keys carrying ``unit`` as a suffix (``mean_um``, ...)."""
    return {f"{key}_{unit}" if key in NUMBER_KEYS else key: value
            for key, value in entry.items()}


def _contribution_entries(alone, shares, key, index=()):
    return {name: {"standard_uncertainty": _optional(alone[name][key][index]),
                   "share": _optional(shares[key][name][index])} for name in alone}


def _figure_set(standard, case):
    """The figures of ``standard`` the Monte Carlo propagates to: a positioning standard's
    (``all``: every defined one) or ISO 230-3's of a thermal case; the standards without a
    public definition are refused."""
    if standard in UNDEFINED:
        title, reason = UNDEFINED[standard]
        raise InputError(f"{title} has no figures in feedaxis: {reason}",
                         parameter="--standard")
    if standard == THERMAL:
        check_thermal(case)
        return ThermalFigures(case.positioning)
    return FigureSet(standard)


def _figures(names, data_figures, values, alone, shares, moments):
    """{figure key: entry in µm} in the standard's order, as ``compare`` keys them."""
    figures = {}
    for key, name in names.items():
        if key not in values:
            continue
        entry = _interval_entry(data_figures[key], engine.summarise(values[key]), (),
                                moments)
        entry["contributions"] = {source: _with_unit(c, "um") for source, c in
                                  _contribution_entries(alone, shares, key).items()}
        figures[key] = {"name": name, **_with_unit(entry, "um")}
    return figures


def _parameters(result, measurement, values, alone, shares, seed, chunk, progress):
    """Fill the parameters' entries, after checking the linearisation on a few refits (and
    refitting on :data:`REFIT_TRIALS` trials instead when it fails the check)."""
    linear = measurement.parameters
    summary = engine.summarise(values["parameters"])
    check = engine.run(lambda streams, trials, active, skip: {
        "deviation": measurement.trial_deviations(streams, trials, active)},
        result.inputs, CHECK_TRIALS, seed, CHECK_TRIALS, block=SPECIAL_BLOCK)["deviation"]
    worst = measurement.linearisation_check(
        check, linear.of(check - measurement.deviation_um), summary.standard_uncertainty)
    method = {"method": "linearised fit", "checked_trials": CHECK_TRIALS,
              "largest_refit_difference_in_u": worst, "tolerance_in_u": LINEARISATION_TOLERANCE}
    if not worst <= LINEARISATION_TOLERANCE and np.isfinite(worst):
        refits = engine.run(measurement.refit_sample, result.inputs, REFIT_TRIALS, seed,
                            min(chunk, REFIT_TRIALS), block=SPECIAL_BLOCK + 1,
                            progress=progress)
        values.update(refits)
        summary = engine.summarise(values["parameters"])
        method = {**method, "method": f"refit on each of {REFIT_TRIALS} trials (the "
                                      "linearisation failed its check)"}
    result.parameter_method = method
    units = {f"{e.name}.{p.name}": p.unit for e in linear.model.effects for p in e.parameters}
    for index, key in enumerate(linear.keys):
        if not linear.determined[index]:
            result.undetermined[key] = linear.undetermined[key]
            continue
        entry = _interval_entry(linear.estimate[index], summary, (index,), result.moments)
        entry["fit_standard_uncertainty"] = float(linear.gum_u[index])
        entry["contributions"] = _contribution_entries(alone, shares, "parameters", (index,))
        result.parameters[key] = {"unit": units[key], **entry}


def _table(table, values_um, alone, moments):
    """The table's points with their values, standard uncertainties (None without a
    variance) and intervals per direction, and each input's share of the summed variance
    over the points."""
    summary = engine.summarise(values_um)
    has_u = "standard_uncertainty" in moments
    u = summary.standard_uncertainty if has_u else np.full_like(summary.mean, np.nan)
    sides = {}
    for column, side in enumerate(("forward", "reverse")):
        sides[side] = {
            "value_um": table.values_um[:, column].tolist(),
            "standard_uncertainty_um": [_optional(v) for v in u[:, column]],
            "coverage_interval_um": summary.symmetric[:, :, column].T.tolist(),
            "shortest_coverage_interval_um": summary.shortest[:, :, column].T.tolist()}
    total = sum(float(np.sum(np.square(u["table_um"]))) for u in alone.values())
    return {"source": table.source, "included": list(table.included),
            "trials": int(values_um.shape[0]), "position_mm": table.position_mm.tolist(), **sides,
            "largest_standard_uncertainty_um": float(np.max(u)) if has_u else None,
            "contributions": {name: {"share": float(np.sum(np.square(u["table_um"]))) / total
                                     if total and has_u else None}
                              for name, u in alone.items()}}


def _notes(measurement, correction):
    """What the reader of the results should know about their scope."""
    notes = []
    if not measurement.repeatability.available:
        notes.append("one reading per target and no model: the repeatability of the "
                     "readings is not in the result (give --model to estimate it from the "
                     "fit's residual)")
    skipped = [name for name, c in CONTRIBUTIONS.items()
               if c.with_correction_only and not correction]
    if skipped:
        notes.append(f"not corrected to 20 °C ({OPTION}): {', '.join(skipped)} do not apply; "
                     "ISO 230-2 reports at 20 °C")
    if isinstance(measurement.repeatability, ReadingNoise):
        return notes + _reading_notes(measurement.repeatability)
    counts = measurement.repeatability.counts
    if REPEATABILITY in measurement.inputs and counts.max() > 1:
        runs = int(np.median(counts))
        notes.append(f"the repeatability moves each target's mean by its type A uncertainty "
                     f"(JCGM 101 §6.4.9); the standard deviations s_i in R and A (VDI: Ps, "
                     f"P) are the test's own, and from {runs} runs each is itself uncertain "
                     f"by about "
                     f"{100 / np.sqrt(2 * (runs - 1)):.0f} % (1/sqrt(2(n - 1))): the sampling "
                     "of the machine's repeatability, not a measurement uncertainty")
        few = _few_runs(measurement.repeatability)
        if few:
            warnings.warn(few)
            notes.insert(0, few)
    return notes


def _reading_notes(noise):
    """What the per-reading noise model of a thermal test means for its figures."""
    if not noise.available:
        return ["no three adjacent targets read in two successive runs: the readings' "
                "scatter is not estimated and not in the result"]
    return [f"ISO 230-3: every reading moves on its own by σ = {noise.sigma_um:.3g} µm "
            f"(ν = {noise.dof}; {noise.source}), so each drift carries the scatter of its "
            "reading and of its target's first reading; the laser's environmental drift "
            "(eve) enters the drifts, a scale or set-up error moves a target's readings "
            "together and cancels"]


def _few_runs(repeatability):
    """The warning of a test with fewer than ISO 230-2's :data:`ISO_RUNS` runs at a target:
    the number of runs every uncertainty here rests on and, with ν = n - 1 <= 2 degrees of
    freedom, why no standard uncertainty is given. None for enough runs."""
    counts = repeatability.counts[repeatability.counts > 1]
    if counts.min() >= ISO_RUNS:
        return None
    runs = (f"{counts.min()}" if counts.min() == counts.max()
            else f"{counts.min()} to {counts.max()}")
    text = (f"the uncertainty of every figure rests on {runs} runs per target and direction "
            f"(ISO 230-2 asks for {ISO_RUNS})")
    missing = [m for m in engine.MOMENTS if m not in repeatability.moments]
    if missing:
        text += (f": the t distribution of ν = {repeatability.dof} degree"
                 f"{'s' if repeatability.dof > 1 else ''} of freedom (n - 1) that moves a "
                 f"target's mean has no {' and no '.join(MOMENT_NAMES[m] for m in missing)} "
                 "(ν <= 2), so no standard uncertainty (nor shares of u²) is given, only the "
                 "95 % coverage intervals, which exist; at least 4 runs give one")
    return text
