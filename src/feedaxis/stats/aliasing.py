"""Whether the targets of a test can tell one wavelength from another: aliasing.

A periodic error at wavelength λ is seen at the targets as the pair cos(2πx/λ), sin(2πx/λ)
(less an offset and a slope, which every positioning model carries). A *rival* wavelength
λ' is one the targets cannot tell from λ: the canonical correlation of the two pairs at the
targets (the cosine of the smallest angle between the planes they span) is at least
``RIVAL_CORRELATION``, so an error at λ' would be taken, for its larger part, for an error at
λ and the reverse. On targets evenly spaced by s every wavelength below 2s has an exact
alias in the band the spacing resolves (correlation 1); on uneven targets the aliases are
near-exact when there are few targets per period of the spacing (an ISO 230-2 test of 11
targets 46 mm apart cannot tell a 10 mm wavelength from 129.5 mm: 0.994).

On uneven targets the rivals are searched over the band the targets resolve as a grid, from
one period over the span to two targets per period at the median spacing
(:func:`feedaxis.stats.spectrum.resolvable_band_per_mm`), every 1/(8 span), leaving out the
main lobe of λ itself (within 1/span of its frequency, Rayleigh's criterion). On an even grid
the one rival is the exact alias, λ's frequency folded into the band.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .spectrum import resolvable_band_per_mm

# At least this canonical correlation between two wavelengths' sinusoids at the targets and
# the targets cannot tell them apart: 0.9² = 81 % of one is taken for the other.
RIVAL_CORRELATION = 0.9
GRID_PER_LOBE = 8  # grid points per 1/span: a peak of width 1/span is met within 1 %
CHUNK = 512  # rival frequencies evaluated at once (memory: targets x CHUNK x 2 floats)
# Uneven targets beyond this are taken as an even grid of their median step (the spectrum
# does the same, :data:`feedaxis.stats.spectrum.MAX_UNEVEN_TARGETS`): only the exact alias
# is checked, as on every even grid, whose other rivals are sidelobes
MAX_SEARCHED_TARGETS = 512


@dataclass(frozen=True)
class Rival:
    """The wavelength (mm) the targets confuse most with the one asked about, and how much
    (canonical correlation, 0 to 1)."""

    wavelength_mm: float
    correlation: float


def _apart(centres_mm, columns):
    """``columns`` (targets x ...) less their least-squares offset-and-slope part."""
    scaled = (centres_mm - centres_mm.mean()) / np.ptp(centres_mm)
    others = np.linalg.qr(np.column_stack((np.ones_like(scaled), scaled)))[0]
    flat = columns.reshape(centres_mm.size, -1)
    return (flat - others @ (others.T @ flat)).reshape(columns.shape)


def _pairs(centres_mm, frequency_per_mm):
    """cos and sin at the targets of each frequency: targets x frequencies x 2."""
    phase = 2 * np.pi * np.multiply.outer(centres_mm, frequency_per_mm)
    return np.stack((np.cos(phase), np.sin(phase)), axis=-1)


def canonical_correlations(centres_mm, frequency_per_mm, rivals_per_mm):
    """The canonical correlation between the sinusoid pair at ``frequency_per_mm`` and the
    pair at each of ``rivals_per_mm``, at the targets ``centres_mm``, an offset and a slope
    taken out of both."""
    own = _apart(centres_mm, _pairs(centres_mm, np.array([frequency_per_mm])))[:, 0, :]
    own_basis = np.linalg.qr(own)[0]
    found = []
    for start in range(0, rivals_per_mm.size, CHUNK):
        pairs = _apart(centres_mm, _pairs(centres_mm, rivals_per_mm[start:start + CHUNK]))
        gram = np.einsum("ika,ikb->kab", pairs, pairs)
        cross = np.einsum("ia,ikb->kab", own_basis, pairs)
        # largest singular value of cross · gram^(-1/2): the cosine of the smallest angle
        values, vectors = np.linalg.eigh(gram)
        values = np.maximum(values, 1e-300)
        inverse_root = np.einsum("kab,kb,kcb->kac", vectors, 1 / np.sqrt(values), vectors)
        whitened = np.einsum("kab,kbc->kac", cross, inverse_root)
        found.append(np.linalg.svd(whitened, compute_uv=False)[:, 0])
    return np.clip(np.concatenate(found), 0.0, 1.0) if found else np.array([])


def _even_step_mm(centres_mm):
    steps = np.diff(centres_mm)
    step = float(np.median(steps))
    return step if np.allclose(steps, step, rtol=1e-3) else None


def _folded(frequency, step_mm, low, lobe):
    """The alias of ``frequency`` on an even grid of ``step_mm`` folded into the band
    (as a one-element array; empty when it is the frequency itself or below the band)."""
    folded = abs(frequency - round(frequency * step_mm) / step_mm)
    keep = folded >= low and abs(folded - frequency) >= lobe
    return np.array([folded]) if keep else np.array([])


def worst_rival(centres_mm, wavelength_mm):
    """The :class:`Rival` of ``wavelength_mm`` the targets ``centres_mm`` (sorted, distinct)
    confuse it with most, in the band they resolve; None when the band holds no rival
    outside the wavelength's own main lobe."""
    centres_mm = np.asarray(centres_mm, dtype=float)
    frequency = 1.0 / wavelength_mm
    low, high = resolvable_band_per_mm(centres_mm)
    lobe = 1.0 / np.ptp(centres_mm)
    step = _even_step_mm(centres_mm)
    if step is not None or centres_mm.size > MAX_SEARCHED_TARGETS:
        grid = _folded(frequency, step or float(np.median(np.diff(centres_mm))), low, lobe)
    else:
        grid = np.arange(low, high + lobe / GRID_PER_LOBE, lobe / GRID_PER_LOBE)
        grid = grid[np.abs(grid - frequency) >= lobe]
    if not grid.size:
        return None
    correlations = canonical_correlations(centres_mm, frequency, grid)
    best = int(np.argmax(correlations))
    return Rival(1.0 / grid[best], float(correlations[best]))


def aliased(centres_mm, wavelength_mm):
    """Why the targets cannot tell ``wavelength_mm`` from another wavelength (None when they
    can): its worst rival reaches ``RIVAL_CORRELATION``."""
    rival = worst_rival(centres_mm, wavelength_mm)
    if rival is None or rival.correlation < RIVAL_CORRELATION:
        return None
    return (f"the {centres_mm.size} targets cannot tell its {wavelength_mm:.4g} mm wavelength "
            f"from {rival.wavelength_mm:.4g} mm (their sinusoids at the targets correlate "
            f"{rival.correlation:.3f}; {RIVAL_CORRELATION} or more is aliasing): an error at "
            f"either would be taken for the other")
