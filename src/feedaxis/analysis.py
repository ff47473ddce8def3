"""Everything the report shows about a fitted model on a positioning case, computed once.

:func:`analyse` returns an :class:`Analysis` (fit result, diagnosis, error ladder, ISO 230-2
comparison, thermal compensation, compensation table); ``feedaxis.report`` only formats it,
as lmfit's ``ModelResult.fit_report`` only reads a fit. ``feedaxis demo`` passes the
diagnosis and ladder its loop already computed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .compensate import THERMAL_EFFECTS, Compensation, compensate, visits
from .comptable import default_spacing_mm, grid_mm, safe_table, verify
from .comptable.table import CompTable
from .diagnose import Diagnosis, diagnose, residual_spectrum
from .effects import CATALOG, Model
from .fit import FitResult, evaluate, fit
from .iso230 import compare, per_target


@dataclass
class Analysis:
    """A model (as fitted) on a positioning case, with every result the report shows.

    ``ladder`` is [(label, residual RMS µm)]: the measurement, then each effect added in
    turn and refitted. ``compensation`` is None unless a thermal model meets a thermal case;
    ``comp_table`` (the table from the model) and ``comp_check`` (its expected ISO 230-2
    figures) are None when no effect of the model goes into a table. ``components`` is
    {effect: error_um} per sample; ``measured_spectrum`` (wavelength_mm, amplitude_um) of
    the measurement less its straight line; ``iso_deviation`` {"+"/"-": (target_mm, mean_um,
    std_um)} of the measurement per approach direction (ISO 230-2); ``run_of_sample`` the
    visit number of each sample at its target (its run) in a time-dependent case, else None.
    """

    case: object
    model: Model
    effects: dict
    result: FitResult
    diagnosis: Diagnosis
    ladder: list
    comparison: dict
    compensation: Compensation | None
    comp_table: CompTable | None
    comp_check: dict | None
    comp_spacing_mm: float
    components: dict
    measured_spectrum: tuple
    iso_deviation: dict
    run_of_sample: object


def error_ladder(case, model):
    """[(label, residual RMS µm)]: nothing, then each effect of ``model`` added in turn, refitted."""
    steps = [("measured", evaluate(Model(), case).rms_um)]
    for count in range(1, len(model.effects) + 1):
        partial = Model(model.effects[:count])
        steps.append((f"+ {model.effects[count - 1].name}", fit(partial, case).rms_um))
    return steps


def detrended_spectrum(case, measured_um, effects):
    """(wavelength_mm, amplitude_um) of the measurement less its least-squares line."""
    position_mm = case.positioning.target_mm
    trend_um = np.polyval(np.polyfit(position_mm, measured_um, 1), position_mm)
    spectrum = residual_spectrum(case, measured_um - trend_um, effects)
    return spectrum.wavelength_mm, spectrum.amplitude_um


def analyse(case, model, effects=None, diagnosis=None, ladder=None):
    """Analyse ``model`` (as fitted) on the positioning ``case``.

    Parameters
    ----------
    case : Case
    model : Model
    effects : dict, optional
        Effects by name the diagnosis may name (default: the catalog).
    diagnosis, ladder : optional
        Already computed for this case and model (``feedaxis demo``'s last round); computed
        here when not given.

    Returns
    -------
    Analysis
    """
    effects = CATALOG if effects is None else effects
    target_mm = case.positioning.target_mm
    spacing_mm = default_spacing_mm(case, None)
    table = safe_table(case, model, grid_mm(target_mm.min(), target_mm.max(), spacing_mm))
    thermal = case.is_thermal and any(name in model for name in THERMAL_EFFECTS)
    result = evaluate(model, case)
    return Analysis(
        case, model, effects, result,
        diagnose(case, model, effects) if diagnosis is None else diagnosis,
        error_ladder(case, model) if ladder is None else ladder,
        compare(case, model), compensate(case, model) if thermal else None,
        table if table.included else None, verify(case, table) if table.included else None,
        spacing_mm, model.components(case),
        detrended_spectrum(case, result.measured_um, effects), iso_deviation(case.positioning),
        visits(case.positioning)[0] if case.positioning.time_s is not None else None)


def iso_deviation(positioning):
    """{"+"/"-": (target_mm, mean_um, std_um)} of the measured runs, each direction present."""
    found = {}
    for sign, label in ((1.0, "+"), (-1.0, "-")):
        if (positioning.direction == sign).any():
            found[label] = per_target(positioning.target_mm, positioning.error_um,
                                      positioning.direction, sign)[:3]
    return found
