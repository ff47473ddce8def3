"""ISO 230-3's figures of a thermal test of a linear axis: the axis cycled under a duty, its
targets read again and again; each reading's thermal drift is its deviation minus that of
the target's first, cold reading (:func:`feedaxis.compensate.thermal_error_um`).

Per approach direction (µm, with the time of each extreme and, when recorded, the air
temperature's change since the start):

- drift at each target: the drift of largest magnitude over the test;
- expansion between the outermost targets: the largest change of their distance, the far
  target's drift less the near one's at the same reading, and the same per metre of their
  distance (µm/m);
- change of the linear positioning error: the largest range of the drifts over the
  targets at one reading.

The same figures of the drift a fitted thermal model predicts (thermal_screw,
ambient_expansion) and of what its compensation leaves (:func:`feedaxis.compensate`).
"""
from __future__ import annotations

import numpy as np

from ..compensate import THERMAL_EFFECTS, compensate, thermal_error_um, visits
from ..errors import InputError
from ..iso230 import target_clusters

THERMAL_TITLE = "ISO 230-3:2020"
CLAUSE = (f"{THERMAL_TITLE}, clause 7, the test for thermal distortion caused by moving "
          "linear axes")
TEST_LENGTH_MM = 2000.0  # clause 7 applies to axes up to 2000 mm, else a 2000 mm part
PROVENANCE = {
    "coverage_factor": None, "adopts": None,
    "confirmed_publicly": "the standard's public scope (afnor.org, nbn.be, iteh.ai): clause 7 "
                          "is the test for thermal distortion caused by moving linear axes, "
                          "for NC machines, quantifying thermal expansion and contraction "
                          "(and angular deformation); it applies to axes up to 2000 mm, a "
                          "longer axis being tested over a representative 2000 mm; it is the "
                          "drift test of ISO/TR 16015:2003, A.4.2",
    "not_confirmed_publicly": "the clause text (sold by ISO): the evaluated quantities "
                              "(drift per target, expansion between the targets near the "
                              "ends, change of the linear positioning error) follow the "
                              "scope's description, not the clause's own formulas; no "
                              "angular deformation is evaluated (a positioning case has no "
                              "angles)"}


def thermal_figures(positioning, drift_um):
    """{key: (name, value µm or µm/m, time_s, sample index)} of the drifts ``drift_um``
    (one per sample of ``positioning``)."""
    return {key: (name, float(value), float(positioning.time_s[sample]), int(sample))
            for key, (name, value, sample) in figure_values(positioning, drift_um).items()}


def figure_values(positioning, drift_um):
    """{key: (name, value, sample index)} of the drifts ``drift_um`` (..., samples): one
    set of drifts, or many Monte Carlo trials' (a leading trials axis; values and sample
    indices then have that axis)."""
    visit = visits(positioning)[0]
    centres_mm, cluster = target_clusters(positioning.target_mm)
    signs = [s for s in (1.0, -1.0) if np.any(positioning.direction == s)]
    figures = {}
    for sign in signs:
        chosen = np.flatnonzero(positioning.direction == sign)
        label = "" if len(signs) == 1 else ("_up" if sign > 0 else "_down")
        named = "" if len(signs) == 1 else (" (+)" if sign > 0 else " (-)")
        index = np.full((centres_mm.size, visit.max() + 1), -1)
        index[cluster[chosen], visit[chosen]] = chosen
        figures.update(_side_figures(index, centres_mm, np.asarray(drift_um, float), label,
                                     named))
    return figures


def _side_figures(index, centres_mm, drift_um, label, named):
    """The figures of one direction from ``index`` (target, visit) -> sample (-1: none)."""
    table = np.where(index >= 0, drift_um[..., index], np.nan)  # (..., target, visit)
    rows = np.flatnonzero(np.any(index >= 0, axis=1))
    figures = {}
    for row in rows:
        value, column = _extreme(table[..., row, :], np.abs)
        figures[f"drift_{centres_mm[row]:g}mm{label}_um"] = (
            f"drift at {centres_mm[row]:g} mm{named}", value, index[row, column])
    if rows.size < 2:
        return figures
    near, far = rows[0], rows[-1]
    expansion = table[..., far, :] - table[..., near, :]
    if np.any(np.isfinite(expansion)):
        value, column = _extreme(expansion, np.abs)
        span_m = (centres_mm[far] - centres_mm[near]) / 1000
        where = f"{centres_mm[near]:g} to {centres_mm[far]:g} mm{named}"
        figures[f"expansion{label}_um"] = (f"expansion {where}", value, index[far, column])
        figures[f"expansion{label}_um_per_m"] = (
            f"expansion per metre {where} (µm/m)", value / span_m, index[far, column])
    within = table[..., rows, :]
    value, column = _extreme(np.nanmax(within, axis=-2) - np.nanmin(within, axis=-2))
    figures[f"linear_error_change{label}_um"] = (
        f"change of the linear positioning error{named}", value,
        np.max(index[rows][:, column], axis=0))
    return figures


def _extreme(values, by=None):
    """(the value of ``values`` (..., visit) whose ``by(value)`` is largest over the visits,
    its visit), NaN (no reading) left out."""
    column = np.nanargmax(values if by is None else by(values), axis=-1)
    return np.take_along_axis(values, column[..., None], axis=-1)[..., 0], column


class ThermalFigures:
    """ISO 230-3's figures of a thermal test as the Monte Carlo propagates to them: the
    same targets, visits and reference readings, the deviations of many trials. Each
    reading is uncertain on its own (a drift cancels what moves a target's readings
    together), so :attr:`per_reading` asks the Monte Carlo for a per-reading noise model."""

    per_reading = True

    def __init__(self, positioning):
        self.positioning, self.title = positioning, THERMAL_TITLE
        self.reference = visits(positioning)[1]
        self._names = {key: name for key, (name, _, _) in figure_values(
            positioning, thermal_error_um(positioning)).items()}

    def names(self):
        """{key: figure name} in the order ``compare`` gives them."""
        return dict(self._names)

    def of(self, target_mm, error_um, direction):
        """{key: value (µm, or µm/m)} of the deviations ``error_um`` (..., samples) of the
        test's readings (``target_mm`` and ``direction`` are the test's own)."""
        error_um = np.asarray(error_um, float)
        drift_um = error_um - error_um[..., self.reference]
        return {key: value for key, (_, value, _) in
                figure_values(self.positioning, drift_um).items()}


def check_thermal(case):
    """Refuse (exit 2) a case that is no thermal test: no duty, or no target read twice."""
    if not case.is_thermal:
        raise InputError(f"{THERMAL_TITLE}'s figures need a thermal case (duty.csv and "
                         "time_s in positioning.csv)", path=case.folder)
    if visits(case.positioning)[0].max() == 0:
        raise InputError(f"{THERMAL_TITLE}'s figures need targets read again and again; "
                         "no target is read twice", path=case.folder)


def thermal_comparison(case, model):
    """``compare``'s ISO 230-3 block of a thermal case: each figure measured, predicted by
    the model's thermal effects and left after their compensation (None without them)."""
    check_thermal(case)
    positioning = case.positioning
    drift_um = thermal_error_um(positioning)
    measured = thermal_figures(positioning, drift_um)
    predicted = compensated = {}
    notes = []
    if any(effect.name in THERMAL_EFFECTS for effect in model.effects):
        left_um = compensate(case, model).left_um
        predicted = thermal_figures(positioning, drift_um - left_um)
        compensated = thermal_figures(positioning, left_um)
    else:
        notes.append("no thermal effect in the model: give --model with thermal_screw "
                     "(feedaxis fit CASE --add thermal_screw) for the predicted and "
                     "compensated figures")
    figures = {}
    for key, (name, value, time, sample) in measured.items():
        figures[key] = {"name": name, "unit": "µm/m" if key.endswith("_per_m") else "µm",
                        "measured_um": value,
                        "predicted_um": predicted[key][1] if key in predicted else None,
                        "compensated_um": compensated[key][1] if key in compensated else None,
                        "time_s": time, **_temperature(positioning, sample)}
    two = ["two targets at least, near the ends of the travel; the data have one"]
    lacking = {} if any(key.startswith("expansion") for key in figures) else {
        "expansion_um": two, "expansion_um_per_m": two, "linear_error_change_um": two}
    span_mm = float(np.ptp(positioning.target_mm))
    if span_mm > TEST_LENGTH_MM:
        longer = (f"targets over at most {TEST_LENGTH_MM:g} mm (a representative part of a "
                  f"longer axis, {CLAUSE}); the data's span {span_mm:g} mm")
        for key in figures:
            if not key.startswith("drift_"):
                lacking.setdefault(key, []).append(longer)
    return {"standard": THERMAL_TITLE, "figures": figures, "clause": CLAUSE,
            "duration_s": float(np.ptp(positioning.time_s)), "needs": lacking, "notes": notes,
            "clauses": {key: CLAUSE for key in figures}, **PROVENANCE}


def thermal_block(case, model):
    """ISO 230-3's block of ``compare``: :func:`thermal_comparison` of a thermal case, or
    why there are no figures."""
    if not case.is_thermal:
        return {"standard": THERMAL_TITLE, "figures": {},
                "unavailable": "not a thermal case (duty.csv and time_s in positioning.csv)"}
    return thermal_comparison(case, model)


def _temperature(positioning, sample):
    """The air temperature's change from the first reading to ``sample`` (K), if recorded."""
    if positioning.ambient_C is None:
        return {}
    first = int(np.argmin(positioning.time_s))
    return {"ambient_change_K": float(positioning.ambient_C[sample]
                                      - positioning.ambient_C[first])}
