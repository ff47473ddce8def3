"""Amplitude spectrum of a residual along the travel, bounded by what the samples resolve.

Samples are first merged into target clusters (:func:`clusters`), so the recorded jitter of
a measured target never refines the grid: the wavelengths run from the travel down to twice
the median cluster spacing (the Nyquist limit of that spacing), with at most
``MAX_FREQUENCIES`` of them, whatever the number of samples.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CLUSTER_TOLERANCE_MM = 1e-4
SPECTRUM_OVERSAMPLING = 5
MAX_FREQUENCIES = 4000
MIN_CLUSTERS = 8


@dataclass
class Spectrum:
    """Amplitude spectrum of the residual along the travel, with marked wavelengths."""

    wavelength_mm: np.ndarray
    amplitude_um: np.ndarray
    marks: dict


def clusters(position_mm, tolerance_mm=CLUSTER_TOLERANCE_MM):
    """(cluster centres in mm, cluster index of each sample): positions closer than
    ``tolerance_mm`` (0.1 µm, above the jitter of a recorded target, below any target
    spacing) to their neighbour are one target."""
    position_mm = np.asarray(position_mm, dtype=float)
    order = np.argsort(position_mm, kind="stable")
    starts = np.concatenate(([True], np.diff(position_mm[order]) > tolerance_mm))
    index = np.empty(position_mm.size, dtype=int)
    index[order] = np.cumsum(starts) - 1
    counts = np.bincount(index)
    return np.bincount(index, position_mm) / counts, index


def resolvable_band_per_mm(centres_mm):
    """(lowest, highest) spatial frequency (1/mm) the cluster centres resolve: one period
    over the span, two samples per period at the median spacing."""
    span_mm = float(np.ptp(centres_mm))
    step_mm = float(np.median(np.diff(centres_mm)))
    return 1.0 / span_mm, 0.5 / step_mm


def frequency_grid(centres_mm):
    """Trial frequencies (1/mm) for an uneven spectrum, at most ``MAX_FREQUENCIES``."""
    low, high = resolvable_band_per_mm(centres_mm)
    step = 1.0 / (SPECTRUM_OVERSAMPLING * np.ptp(centres_mm))
    count = int(min(MAX_FREQUENCIES, max(2, np.floor((high - low) / step) + 1)))
    return np.linspace(low, high, count)


def amplitude_spectrum(position_mm, residual_um):
    """Least-squares amplitude spectrum of the cluster means; FFT on an even grid,
    Lomb-Scargle otherwise. None with fewer than ``MIN_CLUSTERS`` targets."""
    centres_mm, index = clusters(position_mm)
    if centres_mm.size < MIN_CLUSTERS:
        return None
    means_um = np.bincount(index, residual_um) / np.bincount(index)
    spacing = np.diff(centres_mm)
    step_mm = float(np.median(spacing))
    low, high = resolvable_band_per_mm(centres_mm)
    if np.allclose(spacing, step_mm, rtol=1e-3):
        n_fft = 1 << int(np.ceil(np.log2(SPECTRUM_OVERSAMPLING * centres_mm.size)))
        frequency = np.fft.rfftfreq(n_fft, d=step_mm)
        amplitude = 2.0 * np.abs(np.fft.rfft(means_um - means_um.mean(), n_fft)) / centres_mm.size
    else:
        from scipy.signal import lombscargle  # 0.5 s import, only for uneven sampling

        frequency = frequency_grid(centres_mm)
        amplitude = np.abs(lombscargle(centres_mm, means_um, 2 * np.pi * frequency,
                                       floating_mean=True, normalize="amplitude"))
    keep = (frequency >= low * (1 - 1e-12)) & (frequency <= high * (1 + 1e-12))
    return Spectrum(1.0 / frequency[keep], amplitude[keep], {})


def marked_wavelengths(axis, effects):
    """{effect name: wavelength (mm)} of the periodic effects this axis defines."""
    marks = {}
    for name, effect in effects.items():
        try:
            wavelength = effect.wavelength_mm(axis)
        except KeyError:
            continue
        if wavelength:
            marks[name] = float(wavelength)
    return marks


def residual_spectrum(case, residual_um, effects):
    """Amplitude spectrum of the residual along the travel with the effects' wavelengths."""
    marks = marked_wavelengths(case.axis, effects)
    spectrum = amplitude_spectrum(case.positioning.target_mm, residual_um)
    if spectrum is None:
        return Spectrum(np.array([]), np.array([]), marks)
    return Spectrum(spectrum.wavelength_mm, spectrum.amplitude_um, marks)
