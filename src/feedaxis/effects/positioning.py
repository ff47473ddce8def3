"""The positioning kind's effect base: effects adding an error (µm) at each sample of
positioning.csv, and the user's own effects written as plain functions (``@effect``)."""
from __future__ import annotations

import numpy as np

from .base import Effect, Needs


class PositioningEffect(Effect):
    """An effect adding to the positioning deviation (µm) at each sample of positioning.csv;
    :attr:`Effect.needs` names the columns, directions and duty it needs of the case."""

    measurement = "positioning"

    def unavailable(self, case):
        positioning = case.positioning
        if positioning is None:
            return "the case has no positioning.csv"
        for column in self.needs.columns:
            if getattr(positioning, column, None) is None or (
                    column == "direction" and not positioning.has_direction):
                return f"needs the '{column}' column of positioning.csv"
        if self.needs.both_directions and not positioning.bidirectional:
            return "needs samples approached in both directions"
        if self.needs.duty and case.duty is None:
            return "needs duty.csv (the motion history of a thermal test)"
        return super().unavailable(case)


class FunctionEffect(PositioningEffect):
    """An effect from a plain function ``f(case, **values) -> error_um`` (the user API)."""

    def __init__(self, function, name, meaning, parameters, needs=Needs(), wavelength_mm=None,
                 guess=None):
        self.function, self.name, self.meaning = function, name, meaning
        self.parameters, self.needs = tuple(parameters), needs
        self._wavelength_mm, self._guess = wavelength_mm, guess

    def prepare(self, case):
        return lambda values: np.asarray(self.function(case, **values))

    def guess(self, case, residual_um):
        return self._guess(case, residual_um) if self._guess else super().guess(case, residual_um)

    def wavelength_mm(self, axis):
        return self._wavelength_mm


def effect(name, meaning, parameters, needs=Needs(), wavelength_mm=None, guess=None):
    """Decorator turning ``f(case, **params) -> error_um`` into an :class:`Effect`.

    Example (a file loaded with ``--effects my_effects.py``)::

        from feedaxis.effects import Parameter, effect

        @effect("coupling_ripple", "ripple of a worn coupling, period 0.37 mm",
                [Parameter("cos_um", "um", -10, 10), Parameter("sin_um", "um", -10, 10)],
                wavelength_mm=0.37)
        def coupling_ripple(case, cos_um, sin_um):
            phase = 2 * np.pi * case.positioning.target_mm / 0.37
            return cos_um * np.cos(phase) + sin_um * np.sin(phase)
    """
    def wrap(function):
        return FunctionEffect(function, name, meaning, parameters, needs, wavelength_mm, guess)
    return wrap
