"""Tracking report figures as PNG bytes; each takes computed arrays only."""
from __future__ import annotations

import numpy as np

from ..report.plots import _finish, plt


def error_against_time(time_s, measured_um, predicted_um, reversals_s):
    """Tracking deviation measured and predicted against time, reversals marked."""
    figure, axes = plt.subplots(figsize=(9, 3.6))
    axes.plot(time_s, measured_um, color="0.55", lw=0.8, label="measured")
    axes.plot(time_s, predicted_um, color="tab:blue", lw=0.8, label="model")
    for index, t in enumerate(reversals_s):
        axes.axvline(t, color="tab:red", lw=0.5, alpha=0.5,
                     label="velocity reversal" if index == 0 else None)
    return _finish(figure, axes, "time (s)", "actual - reference (µm)",
                   "Tracking deviation against time")


def error_against_velocity(velocity_mm_s, measured_um, residual_um):
    """Deviation and residual against the reference velocity: friction shows as a jump at 0."""
    figure, axes = plt.subplots(figsize=(9, 3.6))
    axes.plot(velocity_mm_s, measured_um, ".", ms=1.5, color="0.55", label="measured")
    axes.plot(velocity_mm_s, residual_um, ".", ms=1.5, color="tab:orange",
              label="residual after the model")
    axes.axvline(0.0, color="tab:red", lw=0.8, label="reversal (v = 0)")
    return _finish(figure, axes, "reference velocity (mm/s)", "µm",
                   "Tracking deviation against velocity")


def residual_spectrum(frequency_hz, amplitude_um, structures):
    """Amplitude spectrum of the residual in Hz, unexplained frequencies marked."""
    figure, axes = plt.subplots(figsize=(9, 3.4))
    axes.loglog(frequency_hz, np.maximum(amplitude_um, 1e-12), lw=0.8, label="residual")
    for structure in structures:
        if structure.frequency_hz:
            axes.axvline(structure.frequency_hz, color="tab:red", ls="--",
                         label=f"unexplained {structure.frequency_hz:.4g} Hz")
    return _finish(figure, axes, "frequency (Hz)", "amplitude (µm)", "Residual spectrum",
                   grid="both")


def contributions(time_s, components):
    """Each effect's change of the predicted deviation against time."""
    figure, axes = plt.subplots(figsize=(9, 3.4))
    for name, values in components.items():
        axes.plot(time_s, values, lw=0.8, label=name)
    return _finish(figure, axes, "time (s)", "contribution (µm)", "Each effect's contribution")
