"""The one map between axis.toml, the effects and the FMUs' parameter names.

Used in both directions: model -> FMU (:func:`neutral_fmu_parameters`, under which
``Model.fmu_parameters`` lays each effect's own values) and FMU -> axis.toml
(``feedaxis.cosim.scenarios.base.axis_values``, which writes the axis of a simulated test), and
by the tracking loop for ``[servo]`` (:func:`servo_to_fmu`). It imports nothing from
feedaxis, so every package can use it. ``tests/measurement/test_catalog_contract.py``
checks every name here and every name an effect writes against the built FMUs.
"""
from __future__ import annotations

ISO_REFERENCE_TEMPERATURE_C = 20.0

# axis.toml table -> FMU -> keys the FMU takes from it, under the same name. A key taken by
# several FMUs is one property of the axis: they must agree (one axis has one screw).
AXIS_KEYS = {
    "screw": {
        "GeometricError": ("lead_mm", "length_m", "diameter_m", "density_kg_m3",
                           "youngs_modulus_Pa", "support", "fixed_end_mm"),
        "StepperError": ("lead_mm",),
        "ThermalScrew": ("length_m", "diameter_m", "density_kg_m3", "specific_heat_J_kgK",
                         "expansion_per_K", "nut_length_m", "bearing_length_m", "fixed_end_mm"),
    },
    "motor": {"StepperError": ("step_angle_deg", "error_period_steps")},
}

# axis.toml [servo] key -> NpidServo parameter; "controller" (pid / npid / cascade) is the
# FMU's "controller" (its boolean "nonlinear", NPID on a PID, stays false)
SERVO_KEYS = {"controller": "controller", "kp_V_per_mm": "kp_V_per_mm",
              "ki_V_per_mm_s": "ki_V_per_mm_s", "kd_V_s_per_mm": "kd_V_s_per_mm",
              "ko_per_mm": "ko_per_mm", "e_max_mm": "e_max_mm",
              "force_constant_N_per_V": "force_constant_N_per_V", "loop_step_s": "time_step_s",
              "kp_per_s": "kp_per_s", "kv_V_s_per_mm": "kv_V_s_per_mm", "tn_s": "tn_s",
              "velocity_feedforward": "velocity_feedforward"}
# the [servo] keys of each controller (the others keep the FMU's defaults)
CONTROLLER_KEYS = {"pid": ("kp_V_per_mm", "ki_V_per_mm_s", "kd_V_s_per_mm"),
                   "npid": ("kp_V_per_mm", "ki_V_per_mm_s", "kd_V_s_per_mm", "ko_per_mm",
                            "e_max_mm"),
                   "cascade": ("kp_per_s", "kv_V_s_per_mm", "tn_s", "velocity_feedforward")}

# FMU parameters the positioning effects set, at the values that switch every effect off
# (error 0 µm); each effect's ``fmu_parameters`` overrides its own
NEUTRAL = {
    "GeometricError": {"offset_um": 0.0, "slope_um_per_mm": 0.0, "eccentricity_cos_um": 0.0,
                       "eccentricity_sin_um": 0.0, "backlash_um": 0.0, "sag_enabled": False},
    "StepperError": {"harmonic1_cos_um": 0.0, "harmonic1_sin_um": 0.0,
                     "harmonic2_cos_um": 0.0, "harmonic2_sin_um": 0.0},
    "ThermalScrew": {"k3_W_per_mm_min": 0.0, "k4_W_per_mm_min": 0.0,
                     "reference_ambient_C": ISO_REFERENCE_TEMPERATURE_C},
}


def fmu_axis_keys(table, fmu):
    """The keys of axis.toml ``[table]`` that ``fmu`` takes (empty when none)."""
    return AXIS_KEYS[table].get(fmu, ())


def neutral_fmu_parameters(axis):
    """{FMU: {parameter: value}} from the axis alone, every effect switched off."""
    tables = {"screw": axis.screw, "motor": axis.motor}
    return {fmu: {**{key: tables[table][key] for table in AXIS_KEYS
                     for key in fmu_axis_keys(table, fmu) if key in tables[table]}, **neutral}
            for fmu, neutral in NEUTRAL.items()}


def servo_to_fmu(servo):
    """NpidServo parameters (``ServoParams`` fields) from an axis.toml ``[servo]`` table."""
    return {SERVO_KEYS[key]: value for key, value in servo.items() if key in SERVO_KEYS}


def servo_from_fmu(values):
    """The axis.toml ``[servo]`` table from NpidServo parameter values: the keys of its
    controller (``nonlinear`` on a PID is an NPID; a cascade without integral action,
    ``tn_s`` 0, has no ``tn_s``)."""
    controller = values.get("controller", "pid")
    if controller == "pid" and values.get("nonlinear"):
        controller = "npid"
    keys = CONTROLLER_KEYS[controller] + ("force_constant_N_per_V", "loop_step_s")
    table = {"controller": controller,
             **{key: values[SERVO_KEYS[key]] for key in keys if SERVO_KEYS[key] in values}}
    if controller == "cascade" and not table.get("tn_s"):
        table.pop("tn_s", None)
    return table
