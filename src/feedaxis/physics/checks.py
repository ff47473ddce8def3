"""Parameter checks shared by the physics: one clear error naming the parameter.

The physics is also copied alone into every FMU, so it imports nothing of feedaxis but
this: within feedaxis a refused value is :class:`feedaxis.errors.ParameterError` (bad input,
exit 2); inside an FMU without feedaxis, a plain ``ValueError`` subclass of the same name.
"""
from __future__ import annotations

import math

import numpy as np

try:
    from feedaxis.errors import ParameterError
except ImportError:  # inside an FMU on a host without feedaxis
    class ParameterError(ValueError):
        """A refused parameter value; ``parameter`` names it."""

        def __init__(self, message, parameter=None):
            super().__init__(f"{parameter}: {message}" if parameter else message)
            self.parameter = parameter


def shown(value):
    """``value`` as a message shows it: a NumPy scalar as the plain number it holds."""
    return repr(value.item() if isinstance(value, np.generic) else value)


def require_finite(name, value):
    """Raise :class:`ParameterError` naming ``name`` unless ``value`` is all finite numbers."""
    if type(value) is float and math.isfinite(value):  # the common case, without NumPy
        return
    try:
        numbers = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"must be a number, got {shown(value)}", name) from None
    if not np.all(np.isfinite(numbers)):
        raise ParameterError(f"must be finite, got {shown(value)}", name)


def require_positive(name, value):
    """Raise :class:`ParameterError` naming ``name`` unless ``value`` is finite and > 0."""
    if type(value) is float and 0.0 < value < math.inf:  # the common case, without NumPy
        return
    require_finite(name, value)
    if not np.all(np.asarray(value, dtype=float) > 0):
        raise ParameterError(f"must be > 0, got {shown(value)}", name)


def require_non_negative(name, value):
    """Raise :class:`ParameterError` naming ``name`` unless ``value`` is finite and >= 0."""
    if type(value) is float and 0.0 <= value < math.inf:  # the common case, without NumPy
        return
    require_finite(name, value)
    if not np.all(np.asarray(value, dtype=float) >= 0):
        raise ParameterError(f"must be >= 0, got {shown(value)}", name)


def require_representable(what, value, positive=True, **parameters):
    """Raise :class:`ParameterError` naming ``parameters`` unless ``value``, a quantity
    derived from them (``what``, with its unit), is a finite float (> 0 if ``positive``).

    Parameters each within their own range can still give a quantity beyond a float's:
    1e300 m squared overflows, 1e-300 m to the fourth power underflows to 0.
    """
    value = float(value)
    if (0.0 < value if positive else -math.inf < value) and value < math.inf:
        return
    given = ", ".join(f"{name} = {shown(number)}" for name, number in parameters.items())
    kind = "a positive finite number" if positive else "a finite number"
    raise ParameterError(f"{given} give {what} = {shown(value)}, not {kind}", next(iter(parameters)))
