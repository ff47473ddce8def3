"""Scripted input sequences for each FMU and the same runs computed by the physics directly.

``direct(name, ...)`` follows the FMU step convention (input k over step k, output after
it) without any FMI code, so the FMUs can be checked against the physics they wrap.
"""
import numpy as np

from feedaxis.physics import circle, geometry, motor, mounting, servo, thermal

STEP_SIZE_S = {"NpidServo": 1e-3, "StepperError": 0.01, "GeometricError": 0.01,
               "ThermalScrew": 1.0, "CircleInterpolator": 0.01}
N_STEPS = {"NpidServo": 1500, "StepperError": 600, "GeometricError": 600, "ThermalScrew": 900,
           "CircleInterpolator": 500}
OUTPUTS = {"NpidServo": ("position_mm", "velocity_mm_s", "tracking_error_mm"),
           "StepperError": ("error_um",), "GeometricError": ("error_um",),
           "ThermalScrew": ("error_um", "elongation_um", "peak_rise_K"),
           "CircleInterpolator": ("first_position_ref_mm", "second_position_ref_mm")}
PARAMETERS = {"NpidServo": {"nonlinear": True},
              "StepperError": {"harmonic2_cos_um": 0.03, "error_period_steps": 4},
              "GeometricError": {"backlash_um": 1.5, "support": "fixed-fixed"},
              "ThermalScrew": {"fixed_end_mm": 120.0, "time_step_s": 0.25},
              "CircleInterpolator": {"direction": -1, "radius_mm": 25.0, "feed_mm_min": 2500.0,
                                     "center_first_mm": 40.0, "ahead_s": 0.01}}


def scripted_inputs(name):
    """Input sequences exercising each FMU: motion back and forth, a force, ambient drift
    (none for the circle interpolator, which has no inputs)."""
    t = np.arange(N_STEPS[name]) * STEP_SIZE_S[name]
    if name == "CircleInterpolator":
        return {}
    if name == "NpidServo":
        return {"position_ref_mm": 5.0 * np.sin(2 * np.pi * 0.7 * t) + 0.2 * (t > 0.8),
                "disturbance_N": 40.0 * np.sin(2 * np.pi * 50 * t) * (t > 0.5)}
    if name == "StepperError":
        return {"position_mm": 0.37 * t}
    if name == "GeometricError":
        position = 2.5 - 2.5 * np.cos(2 * np.pi * t / 3.0)
        return {"position_mm": position, "velocity_mm_s": np.gradient(position, t)}
    position = 250.0 - 240.0 * np.cos(2 * np.pi * t / 10.0)
    return {"position_mm": position, "velocity_mm_s": np.gradient(position, t) * (t < 600),
            "ambient_C": 20.0 + 0.002 * t}


def direct(name, inputs, parameters, step_size_s=None):
    """Outputs of FMU ``name`` computed by feedaxis.physics alone: (t=0 row, step rows).

    ``step_size_s`` defaults to ``STEP_SIZE_S[name]``.
    """
    n = len(next(iter(inputs.values()))) if inputs else N_STEPS[name]
    step_size_s = step_size_s or STEP_SIZE_S[name]
    rows = []
    if name == "CircleInterpolator":
        rows = _circle(n, parameters, step_size_s)
    elif name == "NpidServo":
        loop = servo.Servo(servo.ServoParams(**_only(servo.ServoParams, parameters)),
                           initial_reference_mm=inputs["position_ref_mm"][0])
        rows.append((loop.position_mm, loop.velocity_mm_s, loop.tracking_error_mm))
        for k in range(n):
            loop.advance(step_size_s, inputs["position_ref_mm"][k], inputs["disturbance_N"][k])
            rows.append((loop.position_mm, loop.velocity_mm_s, loop.tracking_error_mm))
    elif name == "StepperError":
        p = {"lead_mm": 1.0, "step_angle_deg": 0.72, "error_period_steps": 10,
             "harmonic1_cos_um": 0.08, "harmonic1_sin_um": 0.06,
             "harmonic2_cos_um": 0.0, "harmonic2_sin_um": 0.0, **parameters}
        position = np.concatenate(([inputs["position_mm"][0]], inputs["position_mm"]))
        error = motor.motor_step_error_um(position, p["lead_mm"], p["step_angle_deg"],
                                          p["error_period_steps"],
                                          (p["harmonic1_cos_um"], p["harmonic2_cos_um"]),
                                          (p["harmonic1_sin_um"], p["harmonic2_sin_um"]))
        rows = error[:, None]
    elif name == "GeometricError":
        rows = _geometric(inputs, parameters, step_size_s)
    else:
        rows = _thermal(inputs, parameters, step_size_s)
    return np.asarray(rows, dtype=float)


def _only(cls, parameters):
    names = set(cls.__dataclass_fields__)
    return {k: v for k, v in parameters.items() if k in names}


def _circle(n_steps, parameters, step_size_s):
    """The interpolator's outputs at t = 0 and after each step: the circle at the step's
    end + ahead_s, each axis's value computed one time at a time."""
    p = {"radius_mm": 10.0, "feed_mm_min": 1000.0, "center_first_mm": 10.0,
         "center_second_mm": 10.0, "direction": 1, "start_deg": 0.0, "lead_in_deg": 45.0,
         "lead_out_deg": 45.0, "ahead_s": 1e-3, **parameters}
    path = circle.CircleInterpolator(p["radius_mm"], p["feed_mm_min"],
                                     (p["center_first_mm"], p["center_second_mm"]),
                                     p["direction"], p["start_deg"], p["lead_in_deg"],
                                     p["lead_out_deg"])
    ends_s = [0.0] + [k * step_size_s + step_size_s for k in range(n_steps)]
    return [[float(path.position_mm(t + p["ahead_s"], axis)) for axis in (0, 1)]
            for t in ends_s]


def _geometric(inputs, parameters, step_size_s):
    p = {"lead_mm": 1.0, "offset_um": 0.2515, "slope_um_per_mm": -0.5084,
         "eccentricity_cos_um": 0.2005, "eccentricity_sin_um": 0.1504, "backlash_um": 0.0,
         "length_m": 0.8, "diameter_m": 0.034, "density_kg_m3": 7800.0,
         "youngs_modulus_Pa": 2.1e11, "support": "fixed-free", "fixed_end_mm": -141.0,
         **parameters}
    table = geometry.gravity_sag_table(p["length_m"], p["diameter_m"], p["density_kg_m3"],
                                       p["youngs_modulus_Pa"], p["support"])
    position = np.concatenate(([inputs["position_mm"][0]], inputs["position_mm"]))
    velocity = np.concatenate(([inputs["velocity_mm_s"][0]], inputs["velocity_mm_s"]))
    direction, rows = 1.0, []
    for k, (x, v) in enumerate(zip(position, velocity)):
        direction = geometry.play_engagement(direction, v * step_size_s * (k > 0),
                                             p["backlash_um"])
        sag = geometry.gravity_sag_error_um(mounting.screw_coordinate_m(x, p["fixed_end_mm"]), table)
        rows.append([geometry.transmission_error_um(
            x, direction, p["lead_mm"], p["offset_um"], p["slope_um_per_mm"],
            p["eccentricity_cos_um"], p["eccentricity_sin_um"], p["backlash_um"], sag)])
    return rows


def _thermal(inputs, parameters, step_size_s):
    params = thermal.ThermalScrewParams(**_only(thermal.ThermalScrewParams, parameters))
    rise = np.zeros(params.n_cells)
    steps = [0.0] + [step_size_s] * len(inputs["position_mm"])
    index = [0] + list(range(len(inputs["position_mm"])))
    rows = []
    for dt, k in zip(steps, index):
        x = inputs["position_mm"][k]
        rise = thermal.advance(params, rise, dt, x, inputs["velocity_mm_s"][k] * 60.0)
        rows.append((thermal.thermal_error_um(params, rise, x, inputs["ambient_C"][k] - 20.0),
                     thermal.screw_elongation_um(params, rise, params.length_m), rise.max()))
    return rows


def direct_axis(system, inputs):
    """The four-FMU axis composed from feedaxis.physics with the master's multi-rate scheme.

    Same scheme as :mod:`feedaxis.cosim.system`: the servo steps first; StepperError and
    GeometricError see its position and velocity at the end of the same macro step; the
    thermal screw steps every ``ratio`` macro steps with the inputs of the macro step that
    ends its step and holds its outputs in between. Returns {signal name: array}, one
    value per macro step (the value at its end).
    """
    h = system.macro_step_s
    values = {c.name: c.parameters for c in system.components}
    servo_rows = direct("NpidServo", {k: inputs[k] for k in ("position_ref_mm", "disturbance_N")},
                        values["NpidServo"], h)[1:]
    position, velocity = servo_rows[:, 0], servo_rows[:, 1]
    result = {f"NpidServo.{name}": servo_rows[:, i] for i, name in enumerate(OUTPUTS["NpidServo"])}
    result["StepperError.error_um"] = direct(
        "StepperError", {"position_mm": position}, values["StepperError"], h)[1:, 0]
    result["GeometricError.error_um"] = direct(
        "GeometricError", {"position_mm": position, "velocity_mm_s": velocity},
        values["GeometricError"], h)[1:, 0]
    ratio = system.ratio(system.component("ThermalScrew"))
    ends = np.arange(ratio - 1, position.size, ratio)
    initial = {"position_mm": inputs["position_ref_mm"][:1], "velocity_mm_s": [0.0],
               "ambient_C": inputs["ambient_C"][:1]}
    stepped = {"position_mm": position[ends], "velocity_mm_s": velocity[ends],
               "ambient_C": inputs["ambient_C"][ends]}
    thermal_rows = np.vstack([direct("ThermalScrew", initial, values["ThermalScrew"])[:1],
                              direct("ThermalScrew", stepped, values["ThermalScrew"],
                                     ratio * h)[1:]])
    held = thermal_rows[(np.arange(position.size) + 1) // ratio]
    for i, name in enumerate(OUTPUTS["ThermalScrew"]):
        result[f"ThermalScrew.{name}"] = held[:, i]
    result["positioning_error_um"] = sum(result[f"{name}.error_um"] for name in
                                         ("StepperError", "GeometricError", "ThermalScrew"))
    return result
