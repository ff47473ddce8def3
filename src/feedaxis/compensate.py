"""Thermal compensation checked on a thermal case, as Rong et al. 2023 §4.3 and §5.2 (Fig. 13).

The model's thermal effects (thermal_screw, ambient_expansion) predict the thermal error at
every sample; the controller adds the opposite as its correction. A thermal test measures
the thermal error as the drift of each target from its first, cold visit (Fig. 9-13); what
compensation leaves is that drift minus the predicted drift over the same time.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .effects import Model
from .errors import InputError
from .iso230 import target_groups

THERMAL_EFFECTS = ("thermal_screw", "ambient_expansion")


def _figures(before_um, after_um):
    """Max |·| and RMS of the thermal error before and after compensation (µm)."""
    from .fit import rms  # feedaxis.fit imports scipy.optimize (a second): only where used

    return {"max_before_um": float(np.max(np.abs(before_um))),
            "max_after_um": float(np.max(np.abs(after_um))),
            "rms_before_um": rms(before_um), "rms_after_um": rms(after_um)}


@dataclass(frozen=True)
class Compensation:
    """Per sample: the measured thermal error, the correction and what is left (µm).

    ``visit`` counts the visits of each (target, direction) in time order, 0 = the cold
    reference.
    """

    time_s: np.ndarray
    target_mm: np.ndarray
    direction: np.ndarray
    visit: np.ndarray
    measured_um: np.ndarray
    thermal_error_um: np.ndarray
    correction_um: np.ndarray
    left_um: np.ndarray

    def summary(self):
        """Max and RMS before and after over all samples; ``reduction`` of the max (0-1)."""
        figures = _figures(self.thermal_error_um, self.left_um)
        before = figures["max_before_um"]
        figures["reduction"] = 1.0 - figures["max_after_um"] / before if before > 0 else 0.0
        return figures

    def by_target(self):
        """One row per (target, direction): its figures over time."""
        rows = []
        for target_mm, direction in sorted(set(zip(self.target_mm, self.direction))):
            chosen = (self.target_mm == target_mm) & (self.direction == direction)
            rows.append({"target_mm": float(target_mm), "direction": int(direction),
                         **_figures(self.thermal_error_um[chosen], self.left_um[chosen])})
        return rows

    def over_time(self):
        """One row per visit (a run over the targets): mean time and its figures."""
        rows = []
        for visit in np.unique(self.visit):
            chosen = self.visit == visit
            rows.append({"visit": int(visit), "time_s": float(np.mean(self.time_s[chosen])),
                         **_figures(self.thermal_error_um[chosen], self.left_um[chosen])})
        return rows

    def columns(self):
        """{column: values} of the per-sample table, for CSV and JSON."""
        return {"time_s": self.time_s, "target_mm": self.target_mm, "direction": self.direction,
                "measured_um": self.measured_um, "thermal_error_um": self.thermal_error_um,
                "correction_um": self.correction_um, "left_um": self.left_um}

    def to_json(self):
        return {"summary": self.summary(), "by_target": self.by_target(),
                "over_time": self.over_time(),
                "samples": {name: values.tolist() for name, values in self.columns().items()}}


def compensate(case, model):
    """Apply the thermal part of ``model`` as a correction to the thermal case ``case``.

    Parameters
    ----------
    case : Case
        A thermal case (duty.csv, time_s) visiting the same targets repeatedly.
    model : Model
        Fitted; its thermal_screw and ambient_expansion effects make the correction, the
        others (geometry) are constant in time and drop out of the drift.

    Returns
    -------
    Compensation
    """
    if not case.is_thermal:
        raise InputError("compensation needs a thermal case (duty.csv and time_s in "
                         "positioning.csv)", path=case.folder)
    thermal = Model([e for e in model.effects if e.name in THERMAL_EFFECTS], model.values)
    if not thermal.effects:
        raise InputError(f"the model ({' + '.join(model.names) or 'empty'}) has no thermal "
                         f"effect ({' or '.join(THERMAL_EFFECTS)}); identify one first: "
                         "feedaxis fit CASE... --add thermal_screw --out M.toml",
                         parameter="--model")
    from .fit import check_available

    check_available(thermal, case)
    positioning = case.positioning
    visit, reference = visits(positioning)
    if visit.max() == 0:
        raise InputError("no target is measured twice; the thermal error is the drift of a "
                         "target from its first visit", path=case.folder)
    predicted_um = thermal.predict_um(case)
    drift_um = thermal_error_um(positioning)
    return Compensation(positioning.time_s, positioning.target_mm, positioning.direction, visit,
                        positioning.error_um, drift_um, -predicted_um,
                        drift_um - (predicted_um - predicted_um[reference]))


def thermal_error_um(positioning):
    """The thermal error a thermal test measures: each sample's deviation minus that of the
    first visit of its target and direction (µm; Rong et al. 2023 Fig. 9-13)."""
    _, reference = visits(positioning)
    return positioning.error_um - positioning.error_um[reference]


def visits(positioning):
    """Visit number of each sample within its (target, direction), by time; and the index of
    each sample's first visit."""
    groups = target_groups(positioning)
    order = np.lexsort((positioning.time_s, groups))
    sorted_groups = groups[order]
    first = np.flatnonzero(np.r_[True, sorted_groups[1:] != sorted_groups[:-1]])
    starts = np.repeat(first, np.diff(np.r_[first, order.size]))
    visit, reference = np.empty(order.size, dtype=int), np.empty(order.size, dtype=int)
    visit[order] = np.arange(order.size) - starts
    reference[order] = order[starts]
    return visit, reference
