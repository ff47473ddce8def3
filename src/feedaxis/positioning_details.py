"""What the report and ``--json`` show of a positioning analysis beyond the generic
(:func:`feedaxis.analysis.analyse` asks for it through the kind's ``details`` part): the
spectra along the travel, the ISO 230-2 deviation, the model between the targets, the
thermal compensation of a thermal case and the compensation table with its expected
figures (built safe and verified by :mod:`feedaxis.comptable`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .compensate import THERMAL_EFFECTS, Compensation, compensate, visits
from .comptable import default_spacing_mm, grid_mm, safe_table, verify
from .comptable.table import CompTable
from .iso230 import per_target, target_clusters
from .measurement.positioning import marked_wavelengths
from .stats.spectrum import MIN_CLUSTERS, residual_spectrum

DENSE_POINTS_PER_LINE = 200   # a smooth model drawn between its targets
POINTS_PER_PERIOD = 16        # the shortest period of the model's effects, drawn smoothly
MAX_DENSE_POINTS = 20_000     # every line of the dense model together
MAX_PERIODS_READABLE = 20     # more periods over the travel blur into a band ...
ZOOM_PERIODS = 3              # ... so a window of this many periods is drawn beside it


@dataclass
class DenseModel:
    """The model between the targets: lines of points ``position_mm`` with their approach
    ``direction`` and ``line`` (the line each point belongs to: one per approach direction,
    one per run and direction when the model can change from run to run), the prediction
    ``predicted_um`` and each effect's contribution ``components`` {effect: µm} at each
    point, and ``windows`` {effect: (start_mm, stop_mm)}: a few periods of each effect whose
    period is too short to read over the whole travel."""

    position_mm: np.ndarray
    direction: np.ndarray
    line: np.ndarray
    per_run: bool
    predicted_um: np.ndarray
    components: dict
    windows: dict


@dataclass
class PositioningDetails:
    """The positioning views: the spectra (wavelength_mm, amplitude_um) of the residual and
    of the measurement less its straight line (empty, with ``spectrum_missing`` saying why,
    when the targets are too few), with the catalog wavelengths the targets resolve
    (``marks``) and why the others are not marked (``unresolved``); ``iso_deviation``
    {"+"/"-": (target_mm, mean_um, std_um)} of the measurement per approach direction (ISO
    230-2) and ``iso_line`` (offset_um, slope_um_per_mm) the straight line through those
    means; ``run_of_sample`` the visit number of each sample at its target in a
    time-dependent case, else None; ``dense`` the model between the targets
    (:class:`DenseModel`); ``compensation`` when a thermal model meets a thermal case;
    ``comp_table`` (the table from the model) and ``comp_check`` (its expected ISO 230-2
    figures), None when no effect of the model goes into a table."""

    residual_spectrum: tuple
    measured_spectrum: tuple
    spectrum_missing: str | None
    marks: dict
    unresolved: dict
    iso_deviation: dict
    iso_line: tuple
    run_of_sample: object
    dense: DenseModel
    compensation: Compensation | None
    comp_table: CompTable | None
    comp_check: dict | None
    comp_spacing_mm: float


def positioning_details(measurement, model, effects, result):
    """The positioning views of ``model`` (its ``result`` on ``measurement``), as
    :class:`PositioningDetails`: the analysis's ``details`` of a positioning case."""
    case, positioning = measurement.case, measurement.samples
    target_mm = positioning.target_mm
    spacing_mm = default_spacing_mm(case, None)
    table = safe_table(case, model, grid_mm(target_mm.min(), target_mm.max(), spacing_mm))
    thermal = case.is_thermal and any(name in model for name in THERMAL_EFFECTS)
    marks = marked_wavelengths(case.axis, effects)
    residual = residual_spectrum(target_mm, result.residual_um, marks)
    trend_um = (np.polyval(np.polyfit(target_mm, result.measured_um, 1), target_mm)
                if varies(target_mm) else np.mean(result.measured_um))
    measured = residual_spectrum(target_mm, result.measured_um - trend_um, marks)
    targets = target_clusters(target_mm)[0].size
    unresolved = {name: measurement.unresolvable(effects[name]) for name in residual.marks}
    deviation = iso_deviation(positioning)
    run_of_sample = visits(positioning)[0] if positioning.time_s is not None else None
    return PositioningDetails(
        (residual.wavelength_mm, residual.amplitude_um),
        (measured.wavelength_mm, measured.amplitude_um),
        None if residual.wavelength_mm.size else
        f"a spatial spectrum needs at least {MIN_CLUSTERS} targets; the case has {targets}",
        {name: mm for name, mm in residual.marks.items() if not unresolved[name]},
        {name: reason for name, reason in unresolved.items() if reason},
        deviation, straight_line(deviation), run_of_sample,
        dense_model(measurement, model, run_of_sample),
        compensate(case, model) if thermal else None,
        table if table.included else None, verify(case, table) if table.included else None,
        spacing_mm)


def varies(values):
    """Whether ``values`` (finite) hold two distinct ones: ``np.unique(values).size > 1``
    without sorting them (NumPy's unique hashes 10^7 targets for 0.7 s)."""
    return values.size > 1 and values.min() < values.max()


def dense_model(measurement, model, run_of_sample=None):
    """The model between the targets of ``measurement`` (positioning), as a
    :class:`DenseModel`: each line (an approach direction, or a run of ``run_of_sample``
    and a direction) resampled evenly from its first to its last target, its time and
    ambient interpolated along the position, and predicted through the measurement like
    the samples themselves. Empty when no line has two targets."""
    samples, case = measurement.samples, measurement.case
    keys = _line_keys(samples, run_of_sample)
    lines = [(keys == key) & (samples.direction == sign)
             for key in np.unique(keys) for sign in (1.0, -1.0)]
    lines = [chosen for chosen in lines if varies(samples.target_mm[chosen])]
    wavelengths = marked_wavelengths(case.axis, {e.name: e for e in model.effects})
    span_mm = float(np.ptp(samples.target_mm))
    start_mm = float(samples.target_mm.min())
    windows = {name: (start_mm, start_mm + ZOOM_PERIODS * wavelength)
               for name, wavelength in wavelengths.items()
               if span_mm > MAX_PERIODS_READABLE * wavelength}
    if not lines:
        empty = np.zeros(0)
        return DenseModel(empty, empty, empty.astype(int), run_of_sample is not None, empty,
                          {name: empty for name in model.names}, {})
    count = DENSE_POINTS_PER_LINE
    if wavelengths:
        count = max(count, int(np.ceil(span_mm / min(wavelengths.values())
                                       * POINTS_PER_PERIOD)) + 1)
    dense, line = _resampled(samples, lines, max(min(count, MAX_DENSE_POINTS // len(lines)), 2))
    resampled = type(measurement)(case.with_samples(measurement.kind, dense))
    return DenseModel(dense.target_mm, dense.direction, line, run_of_sample is not None,
                      resampled.predict_um(model), resampled.components(model), windows)


def _resampled(samples, lines, count):
    """(Positioning, line number per point): ``count`` points evenly from the first to the
    last target of each line (a boolean mask of ``samples``), its direction, its time and
    ambient interpolated along the position."""
    columns = {"target_mm": [], "direction": [], "time_s": [], "ambient_C": []}
    for chosen in lines:
        position_mm = samples.target_mm[chosen]
        grid_mm = np.linspace(position_mm.min(), position_mm.max(), count)
        columns["target_mm"].append(grid_mm)
        columns["direction"].append(np.full(count, samples.direction[chosen][0]))
        for name in ("time_s", "ambient_C"):
            values = getattr(samples, name)
            if values is not None:
                columns[name].append(_along(position_mm, values[chosen], grid_mm))
    joined = {name: np.concatenate(parts) if parts else None for name, parts in columns.items()}
    dense = replace(samples, **joined, error_um=np.zeros(joined["target_mm"].size), run=None)
    return dense, np.repeat(np.arange(len(lines)), count)


def _line_keys(samples, run_of_sample):
    """Per sample, the line it belongs to besides its direction: its run when the model can
    change from run to run (a time-dependent case, or an ambient recorded per run)."""
    if run_of_sample is not None:
        return np.asarray(run_of_sample)
    if samples.ambient_C is not None and samples.run is not None:
        return np.asarray(samples.run)
    return np.zeros(samples.size, dtype=int)


def _along(position_mm, values, grid_mm):
    """``values`` at ``position_mm`` interpolated linearly onto ``grid_mm`` (samples at one
    position averaged)."""
    unique_mm, index = np.unique(position_mm, return_inverse=True)
    means = np.bincount(index, values) / np.bincount(index)
    return np.interp(grid_mm, unique_mm, means)


def iso_deviation(positioning):
    """{"+"/"-": (target_mm, mean_um, std_um)} of the measured runs, each direction present."""
    found = {}
    for sign, label in ((1.0, "+"), (-1.0, "-")):
        if (positioning.direction == sign).any():
            found[label] = per_target(positioning.target_mm, positioning.error_um,
                                      positioning.direction, sign)[:3]
    return found


def straight_line(per_direction):
    """(offset_um, slope_um_per_mm) of the least-squares line through the mean deviations
    of every direction of ``per_direction`` (as :func:`iso_deviation` gives)."""
    target_mm = np.concatenate([values[0] for values in per_direction.values()])
    mean_um = np.concatenate([values[1] for values in per_direction.values()])
    if not varies(target_mm):
        return float(np.mean(mean_um)), 0.0
    slope, offset = np.polyfit(target_mm, mean_um, 1)
    return float(offset), float(slope)
