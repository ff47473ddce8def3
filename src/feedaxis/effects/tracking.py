"""Tracking effects: each sets parameters of the closed position loop (Anang et al. 2017,
Eq. 1-8, or a drive's cascade).

Names are fixed (other tools use them): servo_plant, coulomb_friction, viscous_friction,
stribeck_friction, constant_force.
The parameter names are those of :class:`feedaxis.physics.servo.ServoParams` and of the
NpidServo FMU, so a fitted model drives the FMU unchanged.
"""
from __future__ import annotations

from dataclasses import fields

import numpy as np

from .base import Effect, Parameter
from .. import kinds
from ..physics.servo import PLANT_BOUNDS, ServoParams

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
        """The neutral values, or what the identification from a recorded controller output
        found for this effect's parameters (:mod:`feedaxis.physics.identify`)."""
        identified = kinds.kind(self.measurement).start_of(case).identified
        found = identified.values if identified is not None else {}
        return {**self.neutral, **{key: value for key, value in found.items()
                                   if key in self.neutral and key in self.from_identified}}

    from_identified: tuple = ()

    def fmu_parameters(self, axis, values):
        return {self.fmu: dict(values)}


class ServoPlant(TrackingEffect):
    """The plant G(s) = b e^{-τs} / (s² + a1 s + a0) of Anang et al. 2017 Eq. 1, identified."""

    name = "servo_plant"
    meaning = ("the plant (motor, screw, table) responds differently from the starting "
               "plant: gain, damping, stiffness or transport delay")
    parameters = (
        Parameter("plant_gain_mm_per_Vs2", "mm/(V.s2)", *PLANT_BOUNDS["plant_gain_mm_per_Vs2"],
                  "b of Eq. 1"),
        Parameter("plant_damping_per_s", "1/s", *PLANT_BOUNDS["plant_damping_per_s"],
                  "a1 of Eq. 1"),
        Parameter("plant_stiffness_per_s2", "1/s2", *PLANT_BOUNDS["plant_stiffness_per_s2"],
                  "a0 of Eq. 1"),
        Parameter("delay_s", "s", *PLANT_BOUNDS["delay_s"], "transport delay of the command"))
    neutral = {p.name: SEED002_PLANT[p.name] for p in parameters}
    screened = False  # its delay moves the loop far from a linear step: always fitted

    def guess(self, case, residual_um):
        """The basin of the case's starting plant (the loop's start,
        :class:`feedaxis.measurement.tracking.Start`: the plant fitted beside a friction)."""
        return {**self.neutral, **(kinds.kind(self.measurement).start_of(case).basin or {})}

    def evidence(self, case, values, contribution_um):
        start = {**self.neutral, **(kinds.kind(self.measurement).start_of(case).plant or {})}
        changes = ", ".join(f"{name} {start[name]:.4g} -> {values[name]:.4g}"
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
    from_identified = ("friction_N",)
    screened = False  # the loop is nonlinear in it: a linear step from 0 understates it
    score_screened = True  # but the exact step shows where it cannot matter
    fitted_with = ("servo_plant",)  # the starting plant, fitted alone, absorbed part of it

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


class StribeckFriction(TrackingEffect):
    """Friction that rises at rest above its Coulomb level: coulomb + (static − coulomb)·
    exp(−(v/v_s)²) opposing the velocity (Armstrong-Hélouvry, Dupont & Canudas de Wit,
    Automatica 30 (1994), Eq. 2 with δ = 2)."""

    name = "stribeck_friction"
    meaning = ("friction is higher at rest than in motion (Stribeck), so the axis sticks at "
               "each reversal and the tracking error spikes as it breaks free")
    parameters = (Parameter("coulomb_N", "N", 0.0, 1e4, "friction in steady motion"),
                  Parameter("static_N", "N", 0.0, 1e4, "friction at rest"),
                  Parameter("stribeck_velocity_mm_s", "mm/s", 1e-3, 1e3,
                            "velocity over which the friction falls from static to Coulomb"))
    neutral = {"coulomb_N": 0.0, "static_N": 0.0, "stribeck_velocity_mm_s": 1.0}
    probe = {"coulomb_N": 1.0, "static_N": 1.0}
    screened = False
    score_screened = True
    fitted_with = ("servo_plant",)

    def guess(self, case, residual_um):
        """No rise yet on the Coulomb friction the loop's start fitted beside its plant
        (:class:`feedaxis.measurement.tracking.Start`): static = coulomb = that level. From
        no friction at all the first step of the fit jumps far beyond the friction (the loop
        is nonlinear in it) and the search can settle in a narrow tall rise (measured on a
        P-PI cascade with feed-forward: static 30 N over 0.8 mm/s against 6 N over 2 mm/s,
        a sum of squares 1.5 times the one from this start)."""
        level = kinds.kind(self.measurement).start_of(case).friction_N or 0.0
        return {**self.neutral, "coulomb_N": level, "static_N": level}

    def evidence(self, case, values, contribution_um):
        return (f"{values['static_N']:.3g} N at rest falling to {values['coulomb_N']:.3g} N "
                f"over {values['stribeck_velocity_mm_s']:.3g} mm/s: "
                + _reversals_text(case, contribution_um))


class ConstantForce(TrackingEffect):
    """A constant axial force: the weight on an inclined axis, a counterbalance, a cable
    chain's pull."""

    name = "constant_force"
    meaning = ("a constant axial force acts on the axis (weight on an inclined axis, a "
               "counterbalance, a cable chain), so the loop holds a steady offset or command")
    parameters = (Parameter("force_N", "N", -1e5, 1e5, "the force along +x"),)
    neutral = {"force_N": 0.0}
    probe = {"force_N": 1.0}
    from_identified = ("force_N",)

    def evidence(self, case, values, contribution_um):
        return (f"a constant force of {values['force_N']:+.3g} N on the axis: "
                f"{np.median(contribution_um):+.3g} µm of steady tracking error")


TRACKING_EFFECTS = (ServoPlant(), CoulombFriction(), ViscousFriction(), StribeckFriction(),
                    ConstantForce())


