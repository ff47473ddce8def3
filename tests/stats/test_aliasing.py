"""Aliasing: which wavelengths the targets of a test cannot tell apart, against known
answers (the alias of an even grid, the canonical correlation computed directly)."""
import numpy as np
import pytest

from feedaxis.examples import LASER_EXAMPLE
from feedaxis.importers.rtl import read_rtl
from feedaxis.stats.aliasing import RIVAL_CORRELATION, aliased, canonical_correlations, worst_rival


def direct_correlation(x, f, g):
    """The cosine of the smallest angle between the two sinusoid planes, offset and slope
    taken out: orthonormal bases and one SVD, pair by pair."""
    def basis(frequency):
        phase = 2 * np.pi * frequency * x
        pair = np.column_stack((np.cos(phase), np.sin(phase)))
        others = np.linalg.qr(np.column_stack((np.ones_like(x), x - x.mean())))[0]
        return np.linalg.qr(pair - others @ (others.T @ pair))[0]
    return np.linalg.svd(basis(f).T @ basis(g), compute_uv=False).max()


def test_the_vectorised_correlations_are_the_direct_ones():
    x = np.sort(np.random.default_rng(3).uniform(0.0, 300.0, 23))
    rivals = np.linspace(0.004, 0.05, 37)
    np.testing.assert_allclose(canonical_correlations(x, 0.1, rivals),
                               [direct_correlation(x, 0.1, g) for g in rivals], atol=1e-10)


def test_an_even_grid_aliases_a_short_wavelength_onto_its_fold():
    """Targets every 5 mm: a 3 mm wavelength (1/3 per mm) folds to |1/3 − 2/5| = 1/15 per mm,
    15 mm, exactly (correlation 1); a 12 mm wavelength lies in the band and has no alias."""
    x = np.arange(0.0, 401.0, 5.0)
    rival = worst_rival(x, 3.0)
    assert rival.wavelength_mm == pytest.approx(15.0) and rival.correlation == pytest.approx(1.0)
    assert "from 15 mm" in aliased(x, 3.0)
    assert worst_rival(x, 12.0) is None and aliased(x, 12.0) is None


def test_the_bundled_laser_test_cannot_resolve_its_lead():
    """11 targets about 46 mm apart (ISO 230-2 staggered) on a 10 mm lead: the phases are
    spread, but a 129.5 mm wavelength looks the same at the targets."""
    targets = np.unique(read_rtl(LASER_EXAMPLE / "X-axis.rtl").target_mm)
    rival = worst_rival(targets, 10.0)
    assert rival.correlation > RIVAL_CORRELATION
    assert aliased(targets, 10.0).startswith("the 11 targets cannot tell its 10 mm wavelength")


def test_dense_staggered_targets_resolve_the_lead():
    """81 targets about 5 mm apart over 400 mm, staggered by up to ±0.5 mm: the 10 mm lead is
    told from every other wavelength (largest correlation well under the limit)."""
    x = np.sort(np.linspace(0, 400, 81) + np.random.default_rng(1).uniform(-0.5, 0.5, 81))
    assert worst_rival(x, 10.0).correlation < 0.5
    assert aliased(x, 10.0) is None
