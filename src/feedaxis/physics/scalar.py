"""One formula for arrays and single values: NumPy for arrays, the math module for floats.

An FMU evaluates the physics at one point per communication step, where NumPy's cost per
call on a scalar (about 1 µs per ufunc, more for ``asarray``) would dominate the step. The
physics functions therefore write each formula once against ``xp`` (``array_module``) and
take their inputs through :func:`values`, so a float stays a float and an array an array.
"""
from __future__ import annotations

import bisect
import math
from typing import NamedTuple

import numpy as np


def is_scalar(value):
    """True for a Python or NumPy float or int (not an array, not a list)."""
    return isinstance(value, (float, int))


def array_module(*inputs):
    """``math`` when every input is a scalar, else ``numpy``."""
    for value in inputs:  # a loop, not all(generator): this runs in every FMU step
        if not isinstance(value, (float, int)):
            return np
    return math


def values(value):
    """``value`` as float when scalar, else as a float ndarray."""
    # is_scalar inlined here and in sign: these run several times in every FMU step
    if isinstance(value, (float, int)):
        return float(value)
    return np.asarray(value, dtype=float)


def sign(value):
    """-1, 0 or +1 by the sign of ``value`` (element-wise for arrays), as ``np.sign``."""
    if isinstance(value, (float, int)):
        return float(value > 0) - float(value < 0)
    return np.sign(values(value))


def clip(value, lower, upper):
    """``value`` limited to [lower, upper] (element-wise for arrays), as ``np.clip``."""
    return min(max(value, lower), upper) if is_scalar(value) else np.clip(value, lower, upper)


class Table(NamedTuple):
    """Samples of y(x), x strictly increasing: as arrays for NumPy, as lists for one float."""

    x: np.ndarray
    y: np.ndarray
    x_list: list
    y_list: list


def table(x, y):
    """A :class:`Table` of the samples ``x``, ``y`` (1-D, same length)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return Table(x, y, x.tolist(), y.tolist())


def interp(value, samples):
    """Piecewise-linear y at ``value`` from a :class:`Table`, as ``np.interp`` (held at the
    end values outside the table). A float takes a bisection on the lists and NumPy's own
    formula, slope·(x - x_j) + y_j, so it equals ``np.interp`` bit for bit."""
    if not is_scalar(value):
        return np.interp(value, samples.x, samples.y)
    x, y = samples.x_list, samples.y_list
    if value >= x[-1]:
        return y[-1]
    if value < x[0]:
        return y[0]
    if value != value:  # NaN, as np.interp returns it
        return value
    j = bisect.bisect_right(x, value) - 1
    return (y[j + 1] - y[j]) / (x[j + 1] - x[j]) * (value - x[j]) + y[j]
