"""The catalog of built-in effects, each a thin wrapper over ``feedaxis.physics``.

Names are fixed (tests and other tools use them): lead_error, gravity_sag,
assembly_eccentricity, motor_step_error, backlash, thermal_screw, ambient_expansion; and
the tracking effects of ``feedaxis.effects.tracking``: servo_plant, coulomb_friction,
viscous_friction. Each evaluates with the same physics function its FMU calls.
"""
from __future__ import annotations

import numpy as np

from ..fmu_map import ISO_REFERENCE_TEMPERATURE_C, fmu_axis_keys
from ..physics import geometry, motor, thermal
from ..physics.mounting import screw_coordinate_m
from .tracking import TRACKING_EFFECTS
from .base import Needs, Parameter
from .positioning import PositioningEffect

THERMAL_SCREW_KEYS = fmu_axis_keys("screw", "ThermalScrew")  # what Eq. 1-19 need
SAG_KEYS = ("length_m", "diameter_m", "density_kg_m3", "youngs_modulus_Pa", "support",
            "fixed_end_mm")


def _targets(case):
    return case.positioning.target_mm


class _PeriodicEffect(PositioningEffect):
    """An effect periodic along the travel; parameters: cosine and sine amplitude (µm)."""

    @property
    def linear(self):
        return self.parameter_names

    def guess(self, case, residual_um):
        """Least-squares cosine and sine amplitudes at the effect's wavelength."""
        phase = 2.0 * np.pi * _targets(case) / self.wavelength_mm(case.axis)
        basis = np.column_stack((np.cos(phase), np.sin(phase), np.ones_like(phase)))
        coefficients = np.linalg.lstsq(basis, residual_um, rcond=None)[0]
        return dict(zip(self.parameter_names, coefficients[:2]))


class LeadError(PositioningEffect):
    """Cumulative lead deviation f1 = a1·y + b1 (Liu 2023, low-frequency part)."""

    name = "lead_error"
    meaning = "the screw's lead differs from nominal, so the error grows linearly with travel"
    parameters = (Parameter("offset_um", "um", -1e4, 1e4, "deviation b1 at position 0"),
                  Parameter("slope_um_per_mm", "um/mm", -1e3, 1e3, "lead deviation a1 per mm"))
    linear = ("offset_um", "slope_um_per_mm")
    fmu = "GeometricError"

    def prepare(self, case):
        position_mm = _targets(case)
        return lambda v: geometry.lead_error_um(position_mm, v["offset_um"], v["slope_um_per_mm"])

    def prepare_separable(self, case):
        """1 and the position written into the columns, a zero base (three evaluations of
        the error held three sample-sized arrays)."""
        position_mm = _targets(case)

        def separate(values, columns_um):
            geometry.lead_error_columns(position_mm, columns_um)

        return separate

    def guess(self, case, residual_um):
        slope, offset = np.polyfit(_targets(case), residual_um, 1)
        return {"offset_um": offset, "slope_um_per_mm": slope}

    def fmu_parameters(self, axis, values):
        return {self.fmu: dict(values)}

    def evidence(self, case, values, contribution_um):
        span_mm = np.ptp(_targets(case))
        return (f"the residual trends {values['slope_um_per_mm']:+.3f} µm/mm, "
                f"{values['slope_um_per_mm'] * span_mm:+.2f} µm over {span_mm:g} mm of travel")


class GravitySag(PositioningEffect):
    """Axial error of the nut on the screw bent by its own weight (Liu 2022 Eq. 3-5).

    Computed from the axis geometry and material, nothing fitted.
    """

    name = "gravity_sag"
    meaning = "the screw sags under its own weight, so the nut travels along a longer arc"
    needs = Needs(screw_keys=SAG_KEYS)
    fmu = "GeometricError"

    def prepare(self, case):
        screw = case.axis.screw
        table = geometry.gravity_sag_table(screw["length_m"], screw["diameter_m"],
                                           screw["density_kg_m3"], screw["youngs_modulus_Pa"],
                                           screw["support"])
        error_um = geometry.gravity_sag_error_um(
            screw_coordinate_m(_targets(case), screw["fixed_end_mm"]), table)
        return lambda v: error_um

    def fmu_parameters(self, axis, values):
        return {self.fmu: {"sag_enabled": True}}

    def evidence(self, case, values, contribution_um):
        screw = case.axis.screw
        return (f"a {screw['support']} screw of {screw['length_m']:g} m x "
                f"{screw['diameter_m'] * 1e3:g} mm sags; over the travel it shortens the "
                f"position by {np.ptp(contribution_um):.3g} µm, the residual's bend")


class AssemblyEccentricity(_PeriodicEffect):
    """Sinusoid of wavelength = lead, amplitude δ·tanθ (Liu 2022 Eq. 1-2)."""

    name = "assembly_eccentricity"
    meaning = ("the bearing contact point sits off the screw axis on a tilted face, so the "
               "table oscillates once per screw turn")
    parameters = (Parameter("cos_um", "um", -100.0, 100.0, "a2, cosine term at the lead"),
                  Parameter("sin_um", "um", -100.0, 100.0, "b2, sine term at the lead"))
    fmu = "GeometricError"

    def wavelength_mm(self, axis):
        return axis.lead_mm

    def prepare(self, case):
        position_mm, lead_mm = _targets(case), case.axis.lead_mm
        return lambda v: geometry.eccentricity_error_um(position_mm, lead_mm, v["cos_um"],
                                                        v["sin_um"])

    def prepare_separable(self, case):
        """The cosine and sine at the lead written into the columns, a zero base (three
        evaluations of the error held five sample-sized arrays)."""
        position_mm, lead_mm = _targets(case), case.axis.lead_mm

        def separate(values, columns_um):
            geometry.eccentricity_columns(position_mm, lead_mm, columns_um)

        return separate

    def fmu_parameters(self, axis, values):
        return {self.fmu: {"eccentricity_cos_um": values["cos_um"],
                           "eccentricity_sin_um": values["sin_um"]}}

    def evidence(self, case, values, contribution_um):
        return (f"peak at {case.axis.lead_mm:.3f} mm = lead, amplitude "
                f"{np.hypot(values['cos_um'], values['sin_um']):.3f} µm (δ·tanθ)")


class MotorStepError(_PeriodicEffect):
    """Rotor angle error periodic over ``error_period_steps`` steps (Liu 2022 Eq. 6, 9-10)."""

    name = "motor_step_error"
    meaning = ("the stepper rotor's angle deviates periodically within its step cycle; "
               "the screw turns it into an axial ripple")
    parameters = (Parameter("harmonic1_cos_um", "um", -100.0, 100.0, "a3, cosine term"),
                  Parameter("harmonic1_sin_um", "um", -100.0, 100.0, "b3, sine term"))
    needs = Needs(motor_keys=("step_angle_deg", "error_period_steps"))
    fmu = "StepperError"

    def wavelength_mm(self, axis):
        return motor.motor_error_period_mm(axis.lead_mm, axis.motor["step_angle_deg"],
                                           axis.motor["error_period_steps"])

    def prepare(self, case):
        position_mm, axis = _targets(case), case.axis
        step_deg, steps = axis.motor["step_angle_deg"], axis.motor["error_period_steps"]
        return lambda v: motor.motor_step_error_um(
            position_mm, axis.lead_mm, step_deg, steps, (v["harmonic1_cos_um"],),
            (v["harmonic1_sin_um"],))

    def fmu_parameters(self, axis, values):
        return {self.fmu: dict(values)}

    def evidence(self, case, values, contribution_um):
        axis = case.axis
        return (f"peak at {self.wavelength_mm(axis):.4f} mm = {axis.motor['error_period_steps']} "
                f"steps x {axis.motor['step_angle_deg']:g}° through the {axis.lead_mm:g} mm lead, "
                f"amplitude {np.hypot(values['harmonic1_cos_um'], values['harmonic1_sin_um']):.3f} µm")


class Backlash(PositioningEffect):
    """Reversal offset ±B/2 by approach direction (ISO 230-2 reversal value B)."""

    name = "backlash"
    meaning = "lost motion in the nut and bearings: the error depends on the approach direction"
    parameters = (Parameter("backlash_um", "um", -1e3, 1e3,
                            "reversal B = mean(+ approach) - mean(- approach)"),)
    linear = ("backlash_um",)
    needs = Needs(columns=("direction",), both_directions=True)
    fmu = "GeometricError"

    def prepare(self, case):
        direction = case.positioning.direction
        return lambda v: geometry.backlash_error_um(direction, v["backlash_um"])

    def prepare_separable(self, case):
        """±1/2 by direction written into the column, a zero base."""
        direction = case.positioning.direction

        def separate(values, columns_um):
            geometry.backlash_columns(direction, columns_um)

        return separate

    def guess(self, case, residual_um):
        direction = case.positioning.direction
        return {"backlash_um": np.mean(residual_um[direction > 0])
                - np.mean(residual_um[direction < 0])}

    def fmu_parameters(self, axis, values):
        return {self.fmu: dict(values)}

    def evidence(self, case, values, contribution_um):
        return (f"approaching in + and in - differs by B = {values['backlash_um']:+.3f} µm "
                "at every target")


class ThermalScrew(PositioningEffect):
    """Feed-driven screw heating TE_m (Rong et al. 2023 Eq. 3-19) through a duty.csv."""

    name = "thermal_screw"
    meaning = ("friction in the nut and the fixed-end bearing heats the screw as the axis "
               "runs; the screw grows and the error grows with position and time")
    parameters = (
        Parameter("k1_W_m2K_per_mm_min", "W/(m2.K)/(mm/min)", 0.0, 0.05, "h = k1 v + k2 (Eq. 17)"),
        Parameter("k2_W_m2K", "W/(m2.K)", 1e-3, 500.0, "h = k1 v + k2 (Eq. 17)"),
        Parameter("k3_W_per_mm_min", "W/(mm/min)", 0.0, 0.05, "bearing heat Q_B = k3 v (Eq. 18)"),
        Parameter("k4_W_per_mm_min", "W/(mm/min)", 0.0, 0.05, "nut heat Q_N = k4 v (Eq. 19)"),
        Parameter("conductivity_W_mK", "W/(m.K)", 1.0, 5000.0, "identified λ (Table 3)"),
        Parameter("fixed_end_mm", "mm", -4e5, 4e5, "axis coordinate P_f of the fixed end "
                  "(on an axis: within twice the screw's reach, see bounds)"),
    )
    linear = ("k3_W_per_mm_min", "k4_W_per_mm_min")
    needs = Needs(columns=("time_s",), screw_keys=THERMAL_SCREW_KEYS, duty=True)
    fmu = "ThermalScrew"

    @staticmethod
    def screw_params(axis, values):
        """ThermalScrewParams from the axis geometry and the identified coefficients."""
        geometry_keys = [k for k in THERMAL_SCREW_KEYS if k != "fixed_end_mm"]
        return thermal.ThermalScrewParams(**{k: axis.screw[k] for k in geometry_keys}, **values)

    def prepare(self, case):
        separate = self.prepare_separable(case)

        def evaluate(values):
            columns_um = np.empty((case.positioning.size, len(self.linear)))
            separate(values, columns_um)
            return columns_um @ [values[name] for name in self.linear]

        return evaluate

    def prepare_separable(self, case):
        """TE per unit k3 and per unit k4 into the columns from one closed-form pass (Eq. 10,
        15-19); a zero base."""
        segments, time_s = case.duty.segments, case.positioning.time_s
        unique_s, sample_time = np.unique(time_s, return_inverse=True)
        position_mm = _targets(case)

        def separate(values, columns_um):
            params = self.screw_params(case.axis, values)
            unit_K = thermal.duty_unit_fields(params, segments, unique_s)
            for index, field in enumerate(unit_K):
                columns_um[:, index] = thermal.thermal_error_um(params, field[sample_time],
                                                                position_mm)

        return separate

    def bounds(self, axis):
        """P_f stays on the side of the axis.toml value: Eq. 15 and 16 differ in sign."""
        limits = super().bounds(axis)
        reach_mm = 1e3 * axis.screw["length_m"] + abs(axis.screw["fixed_end_mm"])
        limits["fixed_end_mm"] = ((1e-6, 2 * reach_mm) if axis.screw["fixed_end_mm"] > 0
                                  else (-2 * reach_mm, 0.0))
        return limits

    def guess(self, case, residual_um):
        table3 = thermal.ThermalScrewParams()
        return {p.name: getattr(table3, p.name) for p in self.parameters[:-1]} | {
            "fixed_end_mm": case.axis.screw["fixed_end_mm"]}

    def fmu_parameters(self, axis, values):
        return {self.fmu: dict(values)}

    def evidence(self, case, values, contribution_um):
        return (f"the error grows while the axis runs and relaxes while it stands "
                f"(duty.csv), up to {np.max(np.abs(contribution_um)):.1f} µm")


class AmbientExpansion(PositioningEffect):
    """TE_a = α·(T_a - 20 °C)·(X - X_ref), X_ref = P_f + offset (Rong et al. 2023 Eq. 1 from the
    fixed end, :func:`~feedaxis.physics.thermal.ambient_error_um`); α and P_f from
    axis.toml, the offset fitted (linear, starting at 0: the screw grows from its fixed end).
    """

    name = "ambient_expansion"
    meaning = ("the whole screw expands from its fixed end with the ambient air temperature, "
               "away from the ISO reference of 20 °C")
    parameters = (Parameter("reference_offset_mm", "mm", -1e4, 1e4,
                            "X_ref - P_f: where the expansion starts, from the fixed end"),)
    linear = ("reference_offset_mm",)
    needs = Needs(columns=("ambient_C",), screw_keys=("expansion_per_K", "fixed_end_mm"))
    fmu = "ThermalScrew"

    def prepare(self, case):
        screw, position_mm = case.axis.screw, _targets(case)
        delta_K = case.positioning.ambient_C - ISO_REFERENCE_TEMPERATURE_C
        return lambda v: thermal.ambient_error_um(
            thermal.ThermalScrewParams(expansion_per_K=screw["expansion_per_K"],
                                       fixed_end_mm=screw["fixed_end_mm"],
                                       ambient_reference_offset_mm=v["reference_offset_mm"]),
            position_mm, delta_K)

    def guess(self, case, residual_um):
        return {"reference_offset_mm": 0.0}

    def fmu_parameters(self, axis, values):
        return {self.fmu: {"reference_ambient_C": ISO_REFERENCE_TEMPERATURE_C,
                           "ambient_reference_offset_mm": values["reference_offset_mm"]}}

    def evidence(self, case, values, contribution_um):
        ambient = case.positioning.ambient_C
        reference_mm = case.axis.screw["fixed_end_mm"] + values["reference_offset_mm"]
        return (f"ambient {ambient.min():.2f}-{ambient.max():.2f} °C; α = "
                f"{case.axis.screw['expansion_per_K'] * 1e6:g} µm/(m·K) from X_ref = "
                f"{reference_mm:.4g} mm gives up to {np.max(np.abs(contribution_um)):.2f} µm")


CATALOG = {effect.name: effect for effect in (
    LeadError(), GravitySag(), AssemblyEccentricity(), MotorStepError(), Backlash(),
    ThermalScrew(), AmbientExpansion(), *TRACKING_EFFECTS)}
