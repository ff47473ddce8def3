"""One formula for arrays and single values: NumPy for arrays, the math module for floats.

An FMU evaluates the physics at one point per communication step, where NumPy's cost per
call on a scalar (about 1 µs per ufunc, more for ``asarray``) would dominate the step. The
physics functions therefore take their inputs through :func:`values` (or
:func:`values_and_module`, which also gives the module ``xp`` to write a formula once
against), so a float stays a float and an array an array.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

# The scalar types (NumPy's float64 is a float). A constant: ``isinstance(value, (float,
# int))`` builds the tuple at every call, and is_scalar is inlined where it runs in every
# FMU step (a Python call costs about as much as the formula it guards).
SCALAR_TYPES = (float, int)


def is_scalar(value):
    """True for a Python or NumPy float or int (not an array, not a list)."""
    return isinstance(value, SCALAR_TYPES)


def values(value):
    """``value`` as float when scalar, else as a float ndarray."""
    if type(value) is float:  # the FMU's case, before the general test
        return value
    if isinstance(value, SCALAR_TYPES):
        return float(value)
    return np.asarray(value, dtype=float)


def values_and_module(value):
    """(:func:`values` of ``value``, ``math``) when scalar, else (:func:`values`, ``numpy``):
    one call where a formula needs both (it runs in every FMU step)."""
    if type(value) is float:  # the FMU's case, before the general test
        return value, math
    if isinstance(value, SCALAR_TYPES):
        return float(value), math
    return np.asarray(value, dtype=float), np


def trailing_axis(value):
    """``value`` as it is when scalar, with a trailing axis when an array (one row per
    element, against per-cell rows)."""
    if isinstance(value, SCALAR_TYPES):
        return value
    return value[..., None]


def clip(value, lower, upper):
    """``value`` limited to [lower, upper] (element-wise for arrays), as ``np.clip``: NaN
    stays NaN. A scalar is compared, not passed through min and max (half the cost: this
    runs in every FMU step)."""
    if isinstance(value, SCALAR_TYPES):
        return clip_float(value, lower, upper)
    return np.clip(values(value), lower, upper)


def clip_float(value, lower, upper):
    """:func:`clip` of one float (what numba compiles for an FMU's step: feedaxis.physics.
    fmu_steps)."""
    return upper if value > upper else lower if value < lower else float(value)


@dataclass(frozen=True, slots=True)
class Table:
    """Samples of y(x), x strictly increasing: as arrays for NumPy, as lists for one float
    (with the slope of each interval, (y_j+1 - y_j) / (x_j+1 - x_j), computed once).
    Slotted: :func:`interp` reads three fields at every FMU step, a NamedTuple's slowly."""

    x: np.ndarray
    y: np.ndarray
    x_list: list
    y_list: list
    slope_list: list


def table(x, y):
    """A :class:`Table` of the samples ``x``, ``y`` (1-D, same length)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return Table(x, y, x.tolist(), y.tolist(), (np.diff(y) / np.diff(x)).tolist())


def interp(value, samples):
    """Piecewise-linear y at ``value`` from a :class:`Table`, as ``np.interp`` (held at the
    end values outside the table). A float takes a bisection on the lists and NumPy's own
    formula, slope·(x - x_j) + y_j, so it equals ``np.interp`` bit for bit."""
    if not isinstance(value, SCALAR_TYPES):
        return np.interp(value, samples.x, samples.y)
    return interp_float(value, samples.x_list, samples.y_list, samples.slope_list)


def interp_float(value, x, y, slope):
    """:func:`interp` of one float over the samples ``x``, ``y`` and the slope of each
    interval (lists here; arrays where numba compiles it for an FMU's step:
    feedaxis.physics.fmu_steps)."""
    if value >= x[-1]:
        return y[-1]
    if value < x[0]:
        return y[0]
    if value != value:  # NaN, as np.interp returns it
        return value
    j = bisect.bisect_right(x, value) - 1
    return slope[j] * (value - x[j]) + y[j]
