"""What the report and ``--json`` show of a tracking analysis beyond the generic
(:func:`feedaxis.analysis.analyse` asks for it through the kind's ``details`` part): the
reference velocity, the reversals and the residual's spectrum in time."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .stats.coloured import periodogram


@dataclass
class TrackingDetails:
    """The tracking views: the reference velocity (mm/s) at each sample, the times of its
    reversals (s), and the residual's amplitude spectrum (frequency_hz, amplitude_um)."""

    velocity_mm_s: np.ndarray
    reversals_s: np.ndarray
    residual_spectrum: tuple


def tracking_details(measurement, model, effects, result):
    """The tracking views of ``model`` (its ``result`` on ``measurement``), as
    :class:`TrackingDetails`."""
    velocity_mm_s = np.gradient(measurement.reference_mm, measurement.time_s)
    step_s = float(np.median(np.diff(measurement.time_s)))
    frequency_hz, power = periodogram(result.residual_um, step_s)
    return TrackingDetails(velocity_mm_s, measurement.reversals_s(),
                           (frequency_hz, 2.0 * np.sqrt(power / result.residual_um.size)))
