"""One formula for arrays and single values: NumPy for arrays, the math module for floats.

An FMU evaluates the physics at one point per communication step, where NumPy's cost per
call on a scalar (about 1 µs per ufunc, more for ``asarray``) would dominate the step. The
physics functions therefore write each formula once against ``xp`` (``array_module``) and
take their inputs through :func:`values`, so a float stays a float and an array an array.
"""
from __future__ import annotations

import math

import numpy as np


def is_scalar(value):
    """True for a Python or NumPy float or int (not an array, not a list)."""
    return isinstance(value, (float, int))


def array_module(*inputs):
    """``math`` when every input is a scalar, else ``numpy``."""
    return math if all(is_scalar(value) for value in inputs) else np


def values(value):
    """``value`` as float when scalar, else as a float ndarray."""
    return float(value) if is_scalar(value) else np.asarray(value, dtype=float)


def sign(value):
    """-1, 0 or +1 by the sign of ``value`` (element-wise for arrays), as ``np.sign``."""
    return float(value > 0) - float(value < 0) if is_scalar(value) else np.sign(values(value))


def clip(value, lower, upper):
    """``value`` limited to [lower, upper] (element-wise for arrays), as ``np.clip``."""
    return min(max(value, lower), upper) if is_scalar(value) else np.clip(value, lower, upper)
