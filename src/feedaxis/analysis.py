"""Everything the report, the text and ``--json`` show about a model on a case, computed
once, for every kind of measurement.

:func:`analyse` returns an :class:`Analysis`: the model's result as it stands, the
diagnosis, the error ladder, the figures of ``compare``, each effect's contribution, and
the kind's own views (``details``: for positioning the spectra along the travel, the ISO
230-2 deviation, the thermal compensation and the compensation table; for tracking the
velocity, the reversals and the residual's spectrum in time). ``feedaxis.report`` and
``feedaxis.text`` only format it, as lmfit's ``ModelResult.fit_report`` only reads a fit;
``feedaxis demo`` passes the diagnosis and ladder its loop already computed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .compensate import THERMAL_EFFECTS, Compensation, compensate, visits
from .comptable import default_spacing_mm, grid_mm, safe_table, verify
from .comptable.table import CompTable
from .diagnose import Diagnosis, diagnose
from .effects import CATALOG, Model
from .fit import FitResult, evaluate, fit
from .iso230 import per_target
from .measurement import kinds_for, measurement_of
from .physics.threads import one_blas_thread
from .stats.coloured import periodogram
from .stats.spectrum import residual_spectrum


@dataclass
class PositioningDetails:
    """The positioning views: the spectra (wavelength_mm, amplitude_um) of the residual and
    of the measurement less its straight line, with the catalog wavelengths (``marks``);
    ``iso_deviation`` {"+"/"-": (target_mm, mean_um, std_um)} of the measurement per
    approach direction (ISO 230-2); ``run_of_sample`` the visit number of each sample at its
    target in a time-dependent case, else None; ``compensation`` when a thermal model meets
    a thermal case; ``comp_table`` (the table from the model) and ``comp_check`` (its
    expected ISO 230-2 figures), None when no effect of the model goes into a table."""

    residual_spectrum: tuple
    measured_spectrum: tuple
    marks: dict
    iso_deviation: dict
    run_of_sample: object
    compensation: Compensation | None
    comp_table: CompTable | None
    comp_check: dict | None
    comp_spacing_mm: float


@dataclass
class TrackingDetails:
    """The tracking views: the reference velocity (mm/s) at each sample, the times of its
    reversals (s), and the residual's amplitude spectrum (frequency_hz, amplitude_um)."""

    velocity_mm_s: np.ndarray
    reversals_s: np.ndarray
    residual_spectrum: tuple


@dataclass
class Analysis:
    """A model (as fitted) on one kind of measurement of a case, with every result shown.

    ``ladder`` is [(label, residual RMS µm)]: the model with no effect, then each effect
    added in turn and refitted; ``comparison`` the figures of ``compare``; ``components``
    {effect: µm} per sample.
    """

    case: object
    model: Model
    effects: dict
    measurement: object
    result: FitResult
    diagnosis: Diagnosis
    ladder: list
    comparison: dict
    components: dict
    details: object

    @property
    def kind(self):
        return self.measurement.kind


def compare(case, model, kind=None):
    """The figures of ``model`` (as it stands) on the ``kind`` samples of ``case``: ISO
    230-2 for positioning, seed 002's tracking error for tracking (a dict for ``--json``)."""
    measurement = measurement_of(case, kind or kinds_for([case], model)[0])
    return measurement.figures(evaluate(model, measurement))


def error_ladder(case, model, kind=None):
    """[(label, residual RMS µm)]: the model with no effect, then each effect of ``model``
    added in turn, refitted."""
    measurement = measurement_of(case, kind or kinds_for([case], model)[0])
    steps = [(measurement.reference_label, evaluate(Model(), measurement).rms_um)]
    for count in range(1, len(model.effects) + 1):
        partial = Model(model.effects[:count])
        steps.append((f"+ {model.effects[count - 1].name}", fit(partial, measurement).rms_um))
    return steps


@one_blas_thread
def analyse(case, model, effects=None, diagnosis=None, ladder=None, kind=None, progress=None):
    """Analyse ``model`` (as fitted) on the ``kind`` samples of ``case``.

    Parameters
    ----------
    case : Case
    model : Model
    effects : dict, optional
        Effects by name the diagnosis may name (default: the catalog).
    diagnosis, ladder : optional
        Already computed for this case and model (``feedaxis demo``'s last round); computed
        here when not given.
    kind : str, optional
        The kind of measurement (default: the model's, else the first the case holds).
    progress : callable, optional
        Called with a label before each step and each fit.

    Returns
    -------
    Analysis
    """
    effects = CATALOG if effects is None else effects
    notify = progress or (lambda label: None)
    measurement = measurement_of(case, kind or kinds_for([case], model)[0])
    notify("model")
    result = evaluate(model, measurement)
    if diagnosis is None:
        diagnosis = diagnose(case, model, effects, notify, measurement.kind)
    if ladder is None:
        notify("error ladder")
        ladder = error_ladder(case, model, measurement.kind)
    notify("figures")
    details = DETAILS[measurement.kind](measurement, model, effects, result)
    return Analysis(case, model, effects, measurement, result, diagnosis, ladder,
                    measurement.figures(result), measurement.components(model), details)


def _positioning_details(measurement, model, effects, result):
    case, positioning = measurement.case, measurement.samples
    target_mm = positioning.target_mm
    spacing_mm = default_spacing_mm(case, None)
    table = safe_table(case, model, grid_mm(target_mm.min(), target_mm.max(), spacing_mm))
    thermal = case.is_thermal and any(name in model for name in THERMAL_EFFECTS)
    residual = residual_spectrum(case, result.residual_um, effects)
    trend_um = np.polyval(np.polyfit(target_mm, result.measured_um, 1), target_mm)
    measured = residual_spectrum(case, result.measured_um - trend_um, effects)
    return PositioningDetails(
        (residual.wavelength_mm, residual.amplitude_um),
        (measured.wavelength_mm, measured.amplitude_um), residual.marks,
        iso_deviation(positioning),
        visits(positioning)[0] if positioning.time_s is not None else None,
        compensate(case, model) if thermal else None,
        table if table.included else None, verify(case, table) if table.included else None,
        spacing_mm)


def _tracking_details(measurement, model, effects, result):
    velocity_mm_s = np.gradient(measurement.reference_mm, measurement.time_s)
    step_s = float(np.median(np.diff(measurement.time_s)))
    frequency_hz, power = periodogram(result.residual_um, step_s)
    return TrackingDetails(velocity_mm_s, measurement.reversals_s(),
                           (frequency_hz, 2.0 * np.sqrt(power / result.residual_um.size)))


DETAILS = {"positioning": _positioning_details, "tracking": _tracking_details}


def iso_deviation(positioning):
    """{"+"/"-": (target_mm, mean_um, std_um)} of the measured runs, each direction present."""
    found = {}
    for sign, label in ((1.0, "+"), (-1.0, "-")):
        if (positioning.direction == sign).any():
            found[label] = per_target(positioning.target_mm, positioning.error_um,
                                      positioning.direction, sign)[:3]
    return found
