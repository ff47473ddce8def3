"""Tail probabilities and quantiles of the F, χ² and normal distributions, from the
scipy.special functions that scipy.stats's distributions evaluate, with their answers at
the edges of the support and for arguments out of range: the same values
(tests/stats/test_distributions.py), without importing scipy.stats, which cost each
analysis command 0.5-0.8 s of its start on top of scipy.optimize.
"""
from __future__ import annotations

import numpy as np
from scipy import special


def f_sf(statistic, dfn, dfd):
    """P(F > ``statistic``) for F with (``dfn``, ``dfd``) degrees of freedom
    (scipy.stats.f.sf)."""
    return _upper_tail(statistic, special.fdtrc, dfn, dfd)


def chi2_sf(statistic, df):
    """P(χ² > ``statistic``) for χ² with ``df`` degrees of freedom (scipy.stats.chi2.sf)."""
    return _upper_tail(statistic, special.chdtrc, df)


def chi2_isf(probability, df):
    """The value χ² exceeds with ``probability`` (scipy.stats.chi2.isf)."""
    return _quantile(probability, lambda q: special.chdtri(df, q), (df,), at_0=np.inf,
                     at_1=0.0)


def chi2_ppf(probability, df):
    """The value χ² stays below with ``probability`` (scipy.stats.chi2.ppf)."""
    return _quantile(probability, lambda q: 2 * special.gammaincinv(df / 2, q), (df,),
                     at_0=0.0, at_1=np.inf)


def norm_sf(z):
    """P(Z > ``z``) for the standard normal (scipy.stats.norm.sf)."""
    return _scalar_or_array(special.ndtr(-np.asarray(z, dtype=float)))


def norm_isf(probability):
    """The value Z exceeds with ``probability`` (scipy.stats.norm.isf)."""
    return _quantile(probability, lambda q: -special.ndtri(q), (), at_0=np.inf, at_1=-np.inf)


def _upper_tail(statistic, tail, *dofs):
    """``tail(*dofs, x)`` on the open support x > 0; 1 at or below 0, 0 at +∞, NaN for a
    NaN statistic or degrees of freedom that are not all > 0."""
    x = np.asarray(statistic, dtype=float)
    inside = (x > 0.0) & (x < np.inf)
    with np.errstate(invalid="ignore"):
        value = np.where(inside, tail(*dofs, np.where(inside, x, 1.0)), 0.0)
    value = np.where(x <= 0.0, 1.0, value)
    return _scalar_or_array(np.where(_valid(dofs) & ~np.isnan(x), value, np.nan))


def _quantile(probability, inverse, dofs, at_0, at_1):
    """``inverse(q)`` for 0 < q < 1, ``at_0`` and ``at_1`` at the ends, NaN beyond them or
    for degrees of freedom that are not all > 0."""
    q = np.asarray(probability, dtype=float)
    inside = (q > 0.0) & (q < 1.0)
    value = np.where(inside, inverse(np.where(inside, q, 0.5)),
                     np.where(q == 0.0, at_0, np.where(q == 1.0, at_1, np.nan)))
    return _scalar_or_array(np.where(_valid(dofs), value, np.nan))


def _valid(dofs):
    """Where every degree of freedom is > 0 (NaN is not), broadcast."""
    valid = np.True_
    for dof in dofs:
        valid = valid & (np.asarray(dof, dtype=float) > 0.0)
    return valid


def _scalar_or_array(values):
    """A NumPy scalar for a 0-d result (as scipy.stats returns), else the array."""
    values = np.asarray(values, dtype=float)
    return values[()] if values.ndim == 0 else values
