"""Amplitude spectrum of a residual along the travel, bounded by what the samples resolve.

Samples are first merged into targets (:func:`feedaxis.iso230.target_clusters`), so the
jitter of a recorded target never refines the grid: the wavelengths run from the travel down
to twice the median target spacing (the Nyquist limit of that spacing), with at most
``MAX_FREQUENCIES`` of them, whatever the number of samples.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..iso230 import target_clusters
SPECTRUM_OVERSAMPLING = 5
MAX_FREQUENCIES = 4000
MIN_CLUSTERS = 8
MAX_UNEVEN_TARGETS = 512


@dataclass
class Spectrum:
    """Amplitude spectrum of the residual along the travel, with marked wavelengths."""

    wavelength_mm: np.ndarray
    amplitude_um: np.ndarray
    marks: dict


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


def amplitude_spectrum(position_mm, residual_um, clusters=None):
    """Least-squares amplitude spectrum of the cluster means; FFT on an even grid,
    a floating-mean periodogram otherwise. None with fewer than ``MIN_CLUSTERS`` targets.
    ``clusters``: the :func:`target_clusters` of ``position_mm``, when already computed."""
    centres_mm, index = clusters or target_clusters(position_mm)
    if centres_mm.size < MIN_CLUSTERS:
        return None
    means_um = np.bincount(index, residual_um) / np.bincount(index)
    spacing = np.diff(centres_mm)
    step_mm = float(np.median(spacing))
    low, high = resolvable_band_per_mm(centres_mm)
    if centres_mm.size > MAX_UNEVEN_TARGETS and not np.allclose(spacing, step_mm, rtol=1e-3):
        centres_mm, means_um = _on_even_grid(centres_mm, means_um, step_mm)
        spacing = np.full(centres_mm.size - 1, step_mm)
    if np.allclose(spacing, step_mm, rtol=1e-3):
        n_fft = 1 << int(np.ceil(np.log2(SPECTRUM_OVERSAMPLING * centres_mm.size)))
        frequency = np.fft.rfftfreq(n_fft, d=step_mm)
        amplitude = 2.0 * np.abs(np.fft.rfft(means_um - means_um.mean(), n_fft)) / centres_mm.size
    else:
        frequency = frequency_grid(centres_mm)
        amplitude = floating_mean_amplitude(centres_mm, means_um, frequency)
    keep = (frequency >= low * (1 - 1e-12)) & (frequency <= high * (1 + 1e-12))
    return Spectrum(1.0 / frequency[keep], amplitude[keep], {})


def floating_mean_amplitude(position_mm, values_um, frequency_per_mm, chunk_elements=2**22):
    """Amplitude √(a² + b²) of the least-squares fit a·cos + b·sin + c at each frequency
    (the generalised Lomb-Scargle periodogram with a floating mean, Zechmeister & Kürster
    2009, A&A 496:577, Eq. 4-9), from the 3 x 3 normal equations, in chunks of frequencies
    of at most ``chunk_elements`` phases."""
    amplitude = np.empty(frequency_per_mm.size)
    step = max(1, chunk_elements // max(position_mm.size, 1))
    n = float(position_mm.size)
    total = values_um.sum()
    for start in range(0, frequency_per_mm.size, step):
        phase = 2 * np.pi * np.outer(frequency_per_mm[start:start + step], position_mm)
        cos, sin = np.cos(phase), np.sin(phase)
        c, s = cos.sum(axis=1), sin.sum(axis=1)
        normal = np.stack([np.stack([(cos * cos).sum(1), (cos * sin).sum(1), c], -1),
                           np.stack([(cos * sin).sum(1), (sin * sin).sum(1), s], -1),
                           np.stack([c, s, np.full_like(c, n)], -1)], -2)
        right = np.stack([cos @ values_um, sin @ values_um, np.full_like(c, total)], -1)
        coefficients = np.linalg.solve(normal + 1e-12 * n * np.eye(3), right[..., None])[..., 0]
        amplitude[start:start + step] = np.hypot(coefficients[:, 0], coefficients[:, 1])
    return amplitude


def _on_even_grid(centres_mm, means_um, step_mm):
    """Means over bins of the median spacing, empty bins interpolated: beyond
    ``MAX_UNEVEN_TARGETS`` targets an FFT on this grid replaces the periodogram, whose cost
    grows with targets x frequencies."""
    edges = np.arange(centres_mm[0], centres_mm[-1] + step_mm, step_mm)
    index = np.clip(np.searchsorted(edges, centres_mm, side="right") - 1, 0, edges.size - 1)
    counts = np.bincount(index, minlength=edges.size)
    sums = np.bincount(index, means_um, minlength=edges.size)
    grid_mm = edges + step_mm / 2
    filled = counts > 0
    return grid_mm, np.interp(grid_mm, grid_mm[filled], sums[filled] / counts[filled])


def residual_spectrum(position_mm, residual_um, marks):
    """Amplitude spectrum of ``residual_um`` at ``position_mm`` along the travel, with
    ``marks`` ({name: wavelength mm}) to draw on it."""
    spectrum = amplitude_spectrum(position_mm, residual_um)
    if spectrum is None:
        return Spectrum(np.array([]), np.array([]), marks)
    return Spectrum(spectrum.wavelength_mm, spectrum.amplitude_um, marks)
