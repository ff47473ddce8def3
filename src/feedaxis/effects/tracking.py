"""Tracking effects: each sets parameters of the closed position loop (Anang et al. 2017 Eq. 1-8).

Names are fixed (other tools use them): servo_plant, coulomb_friction, viscous_friction.
The parameter names are those of :class:`feedaxis.physics.servo.ServoParams` and of the
NpidServo FMU, so a fitted model drives the FMU unchanged.
"""
from __future__ import annotations

from dataclasses import fields

import numpy as np

from .base import Effect, Parameter
from ..physics.servo import ServoParams

SEED002_PLANT = {f.name: f.default for f in fields(ServoParams)}


class TrackingEffect(Effect):
    """An effect on the closed loop: its values replace ``ServoParams`` fields
    (:func:`feedaxis.measurement.servo_params`).

    ``neutral`` holds the values that switch the effect off (the starting model's values);
    ``probe`` the step per parameter used to guess a start by one linearised least-squares
    step (for parameters whose neutral value is 0).
    """

    fmu = "NpidServo"
    measurement = "tracking"
    additive = False
    neutral: dict = {}

    def unavailable(self, case):
        if case.tracking is None:
            return "the case has no tracking.csv"
        if not case.axis.servo:
            return "needs the [servo] table in axis.toml (the controller as set in the drive)"
        return None

    def guess(self, case, residual_um):
        return dict(self.neutral)

    def fmu_parameters(self, axis, values):
        return {self.fmu: dict(values)}


class ServoPlant(TrackingEffect):
    """The plant G(s) = b e^{-τs} / (s² + a1 s + a0) of Anang et al. 2017 Eq. 1, identified."""

    name = "servo_plant"
    meaning = ("the plant (motor, screw, table) responds differently from Anang et al. 2017 Eq. 1: "
               "gain, damping, stiffness or transport delay")
    parameters = (
        Parameter("plant_gain_mm_per_Vs2", "mm/(V.s2)", 1e2, 1e7, "b of Eq. 1"),
        Parameter("plant_damping_per_s", "1/s", 0.0, 1e4, "a1 of Eq. 1"),
        Parameter("plant_stiffness_per_s2", "1/s2", 0.0, 1e5, "a0 of Eq. 1"),
        Parameter("delay_s", "s", 0.0, 0.02, "transport delay of the command"))
    neutral = {p.name: SEED002_PLANT[p.name] for p in parameters}

    def evidence(self, case, values, contribution_um):
        changes = ", ".join(f"{name} {SEED002_PLANT[name]:.4g} -> {values[name]:.4g}"
                            for name in self.parameter_names)
        return f"the fitted plant moves {changes}; it changes the prediction by " \
               f"{np.sqrt(np.mean(contribution_um ** 2)):.3g} µm RMS"


def _reversals_text(case, contribution_um):
    reference = case.tracking.reference_mm
    reversals = int(np.count_nonzero(np.diff(np.sign(np.diff(reference))) != 0))
    return (f"a jump of {np.ptp(contribution_um):.3g} µm peak to peak in the tracking error, "
            f"locked to the {reversals} velocity reversals")


class CoulombFriction(TrackingEffect):
    """Coulomb friction: a force of constant magnitude opposing the velocity."""

    name = "coulomb_friction"
    meaning = ("friction of constant magnitude opposes the motion, so the tracking error "
               "jumps at every velocity reversal")
    parameters = (Parameter("friction_N", "N", 0.0, 1e4,
                            "Coulomb force, smoothed over |v| < 0.1 mm/s"),)
    neutral = {"friction_N": 0.0}
    probe = {"friction_N": 1.0}

    def evidence(self, case, values, contribution_um):
        return f"{values['friction_N']:.3g} N of Coulomb friction: " + _reversals_text(
            case, contribution_um)


class ViscousFriction(TrackingEffect):
    """Viscous friction: a force proportional to the velocity.

    It enters the plant as a1 + b·c/force_constant, so it cannot be told apart from
    ``servo_plant``'s damping when both are fitted (the fit reports it undetermined).
    """

    name = "viscous_friction"
    meaning = "friction grows with speed, so the tracking error follows the velocity"
    parameters = (Parameter("damping_N_s_per_mm", "N.s/mm", 0.0, 1e3,
                            "viscous force per unit velocity"),)
    neutral = {"damping_N_s_per_mm": 0.0}
    probe = {"damping_N_s_per_mm": 0.01}

    def evidence(self, case, values, contribution_um):
        return (f"{values['damping_N_s_per_mm']:.3g} N·s/mm of viscous friction: an error "
                f"following the velocity, {np.max(np.abs(contribution_um)):.3g} µm at most")


TRACKING_EFFECTS = (ServoPlant(), CoulombFriction(), ViscousFriction())

