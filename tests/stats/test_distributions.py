"""feedaxis.stats.distributions against scipy.stats, the reference it stands in for: the same
values over the support, at its edges and beyond, for scalars and arrays; and an analysis
that no longer imports scipy.stats."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.stats

from feedaxis.stats.distributions import (chi2_isf, chi2_ppf, chi2_sf, f_sf, norm_isf,
                                          norm_sf)

STATISTICS = np.array([-np.inf, -1.0, -0.0, 0.0, 5e-324, 1e-12, 0.3, 1.0, 2.5, 17.0, 1e3,
                       1e300, np.inf, np.nan])
PROBABILITIES = np.array([-0.1, 0.0, 5e-324, 1e-300, 1e-12, 1e-3, 0.05, 0.5, 0.95,
                          1 - 1e-12, 1.0, 1.1, np.nan])
DEGREES = (0.5, 1, 2, 3.5, 30, 1e6, 0, -1, np.nan)


def same(ours, theirs):
    """Equal values (NaN where NaN), and a scalar where scipy.stats gives one."""
    assert np.ndim(ours) == np.ndim(theirs)
    np.testing.assert_array_equal(ours, theirs)


@pytest.mark.parametrize("dfn", DEGREES)
@pytest.mark.parametrize("dfd", DEGREES)
def test_the_f_tail_is_scipys(dfn, dfd):
    same(f_sf(STATISTICS, dfn, dfd), scipy.stats.f.sf(STATISTICS, dfn, dfd))
    for statistic in STATISTICS:
        same(f_sf(statistic, dfn, dfd), scipy.stats.f.sf(statistic, dfn, dfd))


def test_the_f_tail_takes_arrays_of_degrees_as_scipy_does():
    dfd = np.array([1.0, 5.0, 40.0, 0.0])
    same(f_sf(2.0, 3, dfd), scipy.stats.f.sf(2.0, 3, dfd))
    same(f_sf(STATISTICS[:, None], 3, dfd), scipy.stats.f.sf(STATISTICS[:, None], 3, dfd))


@pytest.mark.parametrize("df", DEGREES)
def test_the_chi2_tail_and_quantiles_are_scipys(df):
    same(chi2_sf(STATISTICS, df), scipy.stats.chi2.sf(STATISTICS, df))
    same(chi2_isf(PROBABILITIES, df), scipy.stats.chi2.isf(PROBABILITIES, df))
    same(chi2_ppf(PROBABILITIES, df), scipy.stats.chi2.ppf(PROBABILITIES, df))
    for value in (0.25, 2.0, 0.0, 1.0):
        same(chi2_sf(value, df), scipy.stats.chi2.sf(value, df))
        same(chi2_isf(value, df), scipy.stats.chi2.isf(value, df))
        same(chi2_ppf(value, df), scipy.stats.chi2.ppf(value, df))


def test_the_normal_tail_and_quantile_are_scipys():
    same(norm_sf(STATISTICS), scipy.stats.norm.sf(STATISTICS))
    same(norm_isf(PROBABILITIES), scipy.stats.norm.isf(PROBABILITIES))
    for z in (-3.0, 0.0, 4.5, np.inf):
        same(norm_sf(z), scipy.stats.norm.sf(z))
    for q in (1e-9, 0.5, 0.0, 1.0):
        same(norm_isf(q), scipy.stats.norm.isf(q))


def test_a_diagnosis_leaves_scipy_stats_unimported(tmp_path):
    """The analysis's tests take their tails from scipy.special: a positioning diagnosis
    that names backlash never imports scipy.stats (half a second of every command's
    start)."""
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import synthetic as syn; "
            "from feedaxis.case import read_case; from feedaxis.diagnose import diagnose; "
            "from feedaxis.effects import Model; "
            "syn.iso_case(sys.argv[2], 3, backlash_um=2.0); "
            "found = diagnose(read_case(sys.argv[2]), Model([])); "
            "print([c.effect for c in found.candidates]); "
            "print('scipy.stats' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code, str(Path(__file__).parents[1]),
                           str(tmp_path / "case")], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    named, imported = done.stdout.strip().splitlines()[-2:]
    assert "backlash" in named and imported == "False"
