"""Parameter checks shared by the physics: one clear error naming the parameter."""
from __future__ import annotations

import math

import numpy as np


def require_finite(name, value):
    """Raise ValueError naming ``name`` unless every element of ``value`` is a finite number."""
    if type(value) is float and math.isfinite(value):  # the common case, without NumPy
        return
    try:
        numbers = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.all(np.isfinite(numbers)):
        raise ValueError(f"{name} must be finite, got {value!r}")


def require_positive(name, value):
    """Raise ValueError naming ``name`` unless ``value`` is finite and > 0."""
    if type(value) is float and 0.0 < value < math.inf:  # the common case, without NumPy
        return
    require_finite(name, value)
    if not np.all(np.asarray(value, dtype=float) > 0):
        raise ValueError(f"{name} must be > 0, got {value!r}")


def require_non_negative(name, value):
    """Raise ValueError naming ``name`` unless ``value`` is finite and >= 0."""
    require_finite(name, value)
    if not np.all(np.asarray(value, dtype=float) >= 0):
        raise ValueError(f"{name} must be >= 0, got {value!r}")
