"""Least squares of a few columns over many samples, through their Gram matrix: a k x k
problem where a QR or SVD of samples x k costs seconds at 10^6 samples, and no scaled copy
of the columns (one samples x k array fewer at the peak of a fit); or, as stable as an SVD
of the whole, through a QR decomposition taken a block of rows at a time
(:func:`projection`)."""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np
import scipy.linalg


class Columns(NamedTuple):
    """Linear columns computed where they are used, not kept: ``count`` of them;
    ``write(out=None)`` fills ``out`` (samples x count; a new array when None), returns it."""

    count: int
    write: Callable


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


QR_ROWS = 1 << 16  # rows decomposed at a time by projection (3 MB at five columns)


def projection(columns, target):
    """``columns`` (samples x k) times the least-squares coefficients for ``target``, as
    ``np.linalg.lstsq`` finds them (minimum norm where the columns are dependent, its
    cut-off of the singular values) in the memory of a block of rows: R of the Householder
    QR of [columns | target] over ``QR_ROWS`` rows at a time, each block under the triangle
    so far in one buffer LAPACK factors in place (no stacked copy, nor the copy NumPy's QR
    takes: a 500,000 x 7 projection 65 -> 18 ms); the coefficients from the triangle (the
    same singular values). The whole-array lstsq held a copy of the columns and its
    workspace: 380 MB at 10^7 samples of a cubic's four."""
    count = columns.shape[1]
    stacked = np.zeros((count + 1 + min(QR_ROWS, target.size), count + 1), order="F")
    height = 0  # rows of the triangle so far, above the block (none above the first)
    for first in range(0, target.size, QR_ROWS):
        rows = min(QR_ROWS, target.size - first)
        stacked[height:height + rows, :count] = columns[first:first + rows]
        stacked[height:height + rows, count] = target[first:first + rows]
        factored = scipy.linalg.lapack.dgeqrf(stacked[:height + rows], overwrite_a=True)[0]
        height = min(height + rows, count + 1)
        stacked[:height] = np.triu(factored[:height])
    cut_off = np.finfo(float).eps * max(columns.shape)
    coefficients = np.linalg.lstsq(stacked[:count, :count], stacked[:count, count],
                                   rcond=cut_off)[0]
    return columns @ coefficients


def subtract_product(target, columns, coefficients):
    """``target - columns @ coefficients`` written into ``target`` (a sample-sized array of
    its caller's), ``QR_ROWS`` rows of the product at a time: each row's the same dot
    product, without a sample-sized product beside it."""
    for first in range(0, target.size, QR_ROWS):
        target[first:first + QR_ROWS] -= columns[first:first + QR_ROWS] @ coefficients
    return target
