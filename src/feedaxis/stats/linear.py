"""Least squares of a few columns over many samples, through their Gram matrix: a k x k
problem where a QR or SVD of samples x k costs seconds at 10^6 samples, and no scaled copy
of the columns (one samples x k array fewer at the peak of a fit)."""
from __future__ import annotations

import numpy as np


def unit_gram(columns):
    """(Gram matrix of ``columns`` (samples x k) scaled to unit length, the column norms):
    the norms from the Gram matrix's diagonal (a zero column keeps norm 1)."""
    gram = columns.T @ columns
    scale = np.sqrt(np.diag(gram))
    scale[scale == 0.0] = 1.0
    return gram / np.outer(scale, scale), scale


def normal_solve(columns, target):
    """Least-squares coefficients of ``columns`` (samples x k) for ``target``: the normal
    equations of the unit-scaled columns (minimum norm where the columns are dependent)."""
    gram, scale = unit_gram(columns)
    return np.linalg.lstsq(gram, (columns.T @ target) / scale, rcond=None)[0] / scale
