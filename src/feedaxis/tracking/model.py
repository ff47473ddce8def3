"""A tracking model's prediction: the closed loop of ``[servo]`` and the model's effects.

The controller comes from the case's ``[servo]`` table, the plant from ``servo_plant`` (seed
002 Eq. 1 when the model lacks it), friction from the friction effects; the loop is
:func:`feedaxis.physics.servo.simulate`, the NpidServo FMU's physics.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fmu_map import servo_to_fmu
from ..physics.servo import ServoParams, simulate, step_counts
from ..effects.tracking import is_tracking_effect

SETTLING_S = 1.0  # seed 002 measures the tracking error after the first second


def is_tracking(case, model=None):
    """True when ``case`` is compared as a tracking case: it has tracking.csv and either no
    positioning.csv or a model with tracking effects."""
    if case.tracking is None:
        return False
    return case.positioning is None or (
        model is not None and any(is_tracking_effect(e) for e in model.effects))


def servo_params(axis, model, values=None):
    """The loop's :class:`ServoParams` for ``model`` (with ``values``, default its own)."""
    values = model.values if values is None else values
    merged = servo_to_fmu(axis.servo)
    for effect in model.effects:
        if is_tracking_effect(effect):
            merged.update({**effect.neutral, **values[effect.name]})
    return ServoParams(**merged)


@dataclass
class Record:
    """One case's tracking.csv prepared for repeated simulation."""

    case: object
    counts: np.ndarray

    @classmethod
    def of(cls, case):
        return cls(case, step_counts(case.tracking.time_s, case.axis.servo["loop_step_s"]))

    @property
    def measured_um(self):
        """Measured tracking deviation actual - reference (µm, ISO 230-2 sign)."""
        tracking = self.case.tracking
        return (tracking.actual_mm - tracking.reference_mm) * 1e3

    def predicted_um(self, params):
        """Predicted deviation position - reference (µm) under ``params``."""
        tracking = self.case.tracking
        position_mm = simulate(params, tracking.time_s, tracking.reference_mm,
                               tracking.disturbance_N, self.counts)
        return (position_mm - tracking.reference_mm) * 1e3

    def settled(self):
        """Mask of the samples after the first second."""
        time_s = self.case.tracking.time_s
        return time_s >= time_s[0] + SETTLING_S


def components(case, model):
    """{effect: change of the predicted deviation (µm) it makes}: the full model against the
    model with that effect at its neutral values."""
    record = Record.of(case)
    full_um = record.predicted_um(servo_params(case.axis, model))
    parts = {}
    for effect in model.effects:
        without = {**model.values, effect.name: dict(effect.neutral)}
        parts[effect.name] = full_um - record.predicted_um(servo_params(case.axis, model, without))
    return parts

