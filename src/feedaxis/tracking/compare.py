"""Seed 002's tracking figures for a tracking case: measured against predicted."""
from __future__ import annotations

import numpy as np

from ..fit import rms
from .fit import evaluate
from .model import SETTLING_S, Record


def compare(case, model):
    """Max and RMS tracking error (reference - position, mm) measured and predicted, and the
    residual (actual - predicted, µm), over the samples after the first second.

    Returns a dict ready for ``--json``.
    """
    result = evaluate(model, [case])
    settled = Record.of(case).settled()
    if not settled.any():
        settled = np.ones_like(settled)
    measured_mm = -result.measured_um[settled] * 1e-3
    predicted_mm = -(result.measured_um - result.residual_um)[settled] * 1e-3
    residual_um = result.residual_um[settled]
    return {"case": str(case.folder), "kind": "tracking", "effects": list(model.names),
            "samples": int(settled.sum()), "after_s": SETTLING_S,
            "max_tracking_error_mm": {"measured": float(np.max(np.abs(measured_mm))),
                                      "predicted": float(np.max(np.abs(predicted_mm)))},
            "rms_tracking_error_mm": {"measured": rms(measured_mm), "predicted": rms(predicted_mm)},
            "residual_max_um": float(np.max(np.abs(residual_um))),
            "residual_rms_um": rms(residual_um)}
