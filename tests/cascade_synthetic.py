"""Cascade drive records generated from known parameters, independently of feedaxis.physics.

The loop of an industrial drive (case format 1.2): a P position loop commanding a velocity,
around a velocity loop on the measured velocity with optional integral action and velocity
feed-forward, u = kv·(kp·(r − x) + vff·dr/dt − ẋ) + (kv/tn)·∫(bracket), stepped every loop
step with the plant ẍ + a1·ẋ + a0·x = b·(u(t − τ) + F/K_F) integrated by classical
Runge-Kutta with the input held (:func:`tracking_synthetic._plant_rk4`). Friction (Coulomb,
or Stribeck: F_c + (F_s − F_c)·exp(−(v/v_s)²)) acts from the velocity at each step's start,
its sign smoothed linearly over max(0.1 mm/s, the velocity one step of it would change):
within that band the explicit friction would overshoot zero velocity in one step. A
reversal spike adds spike_N·exp(−(t − t_r)/spike_decay_s) to the friction's level, t_r the
loop step at which the velocity last changed sign (friction that breaks away over time).
"""
from __future__ import annotations

import math

import numpy as np

from feedaxis.case import write_case
from tracking_synthetic import _plant_rk4, noise_um

PLANT = {"plant_gain_mm_per_Vs2": 4000.0, "plant_damping_per_s": 5.0,
         "plant_stiffness_per_s2": 0.0, "delay_s": 0.0005}
FORCE_CONSTANT_N_PER_V = 20.0
LOOP_STEP_S = 0.00025
# the four cascades of the tests: P-P and P-PI, with and without velocity feed-forward
CASCADES = {
    "P-P": {"kp_per_s": 40.0, "kv_V_s_per_mm": 0.2},
    "P-P ff": {"kp_per_s": 40.0, "kv_V_s_per_mm": 0.2, "velocity_feedforward": 1.0},
    "P-PI": {"kp_per_s": 40.0, "kv_V_s_per_mm": 0.2, "tn_s": 0.02},
    "P-PI ff": {"kp_per_s": 40.0, "kv_V_s_per_mm": 0.2, "tn_s": 0.02,
                "velocity_feedforward": 1.0},
}


def servo_table(cascade):
    """The axis.toml ``[servo]`` table of a cascade of :data:`CASCADES`."""
    return {"controller": "cascade", **CASCADES[cascade],
            "force_constant_N_per_V": FORCE_CONSTANT_N_PER_V, "loop_step_s": LOOP_STEP_S}


def _velocity_per_volt(plant, h):
    """The velocity (mm/s) one loop step of 1 V held changes, from rest (RK4)."""
    return _plant_rk4(0.0, 0.0, 1.0, plant["plant_stiffness_per_s2"],
                      plant["plant_damping_per_s"], plant["plant_gain_mm_per_Vs2"], h)[1]


def cascade_loop(reference, duration_s, cascade, sample_s=1e-3, plant=None, friction_N=0.0,
                 coulomb_N=0.0, static_N=0.0, stribeck_velocity_mm_s=1.0, force_N=None,
                 spike_N=0.0, spike_decay_s=0.01):
    """Noise-free (time_s, reference_mm, position_mm, control_V) every ``sample_s``.

    ``reference`` and ``force_N`` are functions of time (s); the set-points are ramped
    linearly between samples and sampled at each loop step's start; the loop starts at rest
    on ``reference(0)``. ``control_V`` is the controller output of each sample's last loop
    step (0 at the first sample), as a drive records it.
    """
    plant = {**PLANT, **(plant or {})}
    gains = CASCADES[cascade]
    kp, kv = gains["kp_per_s"], gains["kv_V_s_per_mm"]
    feedforward = gains.get("velocity_feedforward", 0.0)
    integral_gain = kv / gains["tn_s"] if "tn_s" in gains else 0.0
    h = LOOP_STEP_S
    a0, a1, b = (plant["plant_stiffness_per_s2"], plant["plant_damping_per_s"],
                 plant["plant_gain_mm_per_Vs2"])
    whole = int(math.floor(plant["delay_s"] / h + 1e-9))
    early_s = (plant["delay_s"] / h - whole) * h
    per_sample = int(round(sample_s / h))
    n_samples = int(round(duration_s / sample_s)) + 1
    set_points = [reference(i * sample_s) for i in range(n_samples)]
    peak_V = (friction_N + max(coulomb_N, static_N) + spike_N) / FORCE_CONSTANT_N_PER_V
    band_mm_s = max(0.1, peak_V * abs(_velocity_per_volt(plant, h)))
    commands = [0.0] * (whole + 2)
    x1, x2, integral, previous, output = set_points[0], 0.0, 0.0, 0.0, 0.0
    moving, reversed_s = 0.0, -math.inf
    positions, controls = [x1], [0.0]
    for k in range((n_samples - 1) * per_sample):
        sample, within = divmod(k, per_sample)
        start, end = set_points[sample], set_points[min(sample + 1, n_samples - 1)]
        error = start + (end - start) * within / per_sample - x1
        bracket = kp * error + feedforward * (end - start) / sample_s - x2
        integral += 0.5 * (bracket + previous) * h
        previous = bracket
        output = kv * bracket + integral_gain * integral
        commands = commands[1:] + [output]
        force = force_N((sample + 1) * sample_s) if force_N else 0.0
        sign = max(-1.0, min(1.0, x2 / band_mm_s))
        level = friction_N
        if coulomb_N or static_N:
            level += coulomb_N + (static_N - coulomb_N) * math.exp(
                -(x2 / stribeck_velocity_mm_s) ** 2)
        if x2 * moving < 0.0:
            reversed_s = k * h
        moving = x2 if x2 != 0.0 else moving
        level += spike_N * math.exp(-(k * h - reversed_s) / spike_decay_s)
        force -= level * sign
        force_V = force / FORCE_CONSTANT_N_PER_V
        if early_s > 0.0:
            x1, x2 = _plant_rk4(x1, x2, commands[-whole - 2] + force_V, a0, a1, b, early_s)
        x1, x2 = _plant_rk4(x1, x2, commands[-whole - 1] + force_V, a0, a1, b, h - early_s)
        if (k + 1) % per_sample == 0:
            positions.append(x1)
            controls.append(output)
    time_s = np.arange(n_samples) * sample_s
    return time_s, np.array(set_points), np.array(positions), np.array(controls)


def write_cascade_case(folder, record, cascade, seed, with_control=False, noise_scale=1.0):
    """Write a cascade record plus seeded encoder noise (white 0.1 µm + AR(1) 0.3 µm,
    times ``noise_scale``) as a case; ``with_control`` writes the control_V column."""
    time_s, reference_mm, position_mm, control_V = record
    columns = {"time_s": time_s, "reference_mm": reference_mm,
               "actual_mm": position_mm + noise_scale * noise_um(time_s.size, seed) * 1e-3}
    if with_control:
        columns["control_V"] = control_V
    axis = {"name": f"cascade {cascade}", "screw": {"lead_mm": 10.0},
            "servo": servo_table(cascade)}
    return write_case(folder, axis, tracking=columns)


def exciting(t):
    """A reference a drive commissioning engineer would run: 10 mm at 0.5 Hz plus 0.3 mm at
    7 Hz, exciting the loop beyond the slow motion."""
    return 10.0 * math.sin(math.pi * t) + 0.3 * math.sin(2 * math.pi * 7.0 * t)
