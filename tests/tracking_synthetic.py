"""Tracking cases generated from known parameters by a straightforward stepping of the loop.

Independent of ``feedaxis.physics.servo``: the plant ẋ = [[0, 1], [-a0, -a1]] x + [0, b] u
(Anang et al. 2017 Eq. 1) is integrated by classical Runge-Kutta over each 0.1 ms loop step with
the command held, the delayed command switching inside the step where the delay is not a
whole number of steps; the PID (Eq. 6) or NPID (Eq. 8) acts on the reference sampled at
the start of each step; friction and the force from the velocity at the step's start.
A record may start after the motion did (``start_s``: the loop starts at rest that long
before the first sample) and be written late (``record_delay_s``: actual_mm is the position
that long before its time stamp, a measurement delay outside the loop).

Noise (:data:`NOISE_FAMILIES`): white plus a coloured AR(1) part, as encoder traces show,
and the nulls the diagnosis's false-alarm rate is measured on: white, AR(1) up to ρ = 0.95,
Student-t with ν = 3, quantised to the encoder's 0.1 µm, a slow drift, single-sample spikes.
"""
from __future__ import annotations

import math

import numpy as np

from feedaxis.case import write_case
from synthetic import noise_um as null_noise_um

SEED002 = {"plant_gain_mm_per_Vs2": 78020.0, "plant_damping_per_s": 163.0,
           "plant_stiffness_per_s2": 193.3, "delay_s": 0.0012}
SERVO = {"controller": "pid", "kp_V_per_mm": 0.8998, "ki_V_per_mm_s": 0.0006077,
         "kd_V_s_per_mm": 0.005155, "force_constant_N_per_V": 100.0, "loop_step_s": 1e-4}
AXIS = {"name": "synthetic servo", "screw": {"lead_mm": 10.0}, "servo": SERVO}
WHITE_NOISE_UM = 0.1
COLOURED_NOISE_UM = 0.3
COLOURED_POLE = 0.95  # AR(1) coefficient per 1 ms sample


def _plant_rk4(x1, x2, u, a0, a1, b, duration_s):
    """One classical Runge-Kutta step of the plant with the input held."""
    def slope(p, v):
        return v, -a0 * p - a1 * v + b * u
    k1 = slope(x1, x2)
    k2 = slope(x1 + 0.5 * duration_s * k1[0], x2 + 0.5 * duration_s * k1[1])
    k3 = slope(x1 + 0.5 * duration_s * k2[0], x2 + 0.5 * duration_s * k2[1])
    k4 = slope(x1 + duration_s * k3[0], x2 + duration_s * k3[1])
    return (x1 + duration_s / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]),
            x2 + duration_s / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]))


def step_loop(reference, duration_s, sample_s=1e-3, plant=None, servo=None, friction_N=0.0,
              damping_N_s_per_mm=0.0, force_N=None, start_s=0.0, record_delay_s=0.0):
    """Noise-free (time_s, reference_mm, position_mm) sampled every ``sample_s``.

    ``reference`` and ``force_N`` are functions of time (s). The drive receives the
    reference as set-points every ``sample_s`` and interpolates them linearly, sampling
    the result at the start of each loop step; the loop starts at rest on ``reference(0)``.
    The record keeps the samples from ``start_s`` (a whole number of samples) on, its time
    restarted at 0 there; its position is the one ``record_delay_s`` (a whole number of
    loop steps) earlier.
    """
    plant = {**SEED002, **(plant or {})}
    servo = {**SERVO, **(servo or {})}
    h = servo["loop_step_s"]
    a0, a1, b = (plant["plant_stiffness_per_s2"], plant["plant_damping_per_s"],
                 plant["plant_gain_mm_per_Vs2"])
    whole = int(math.floor(plant["delay_s"] / h + 1e-9))
    early_s = (plant["delay_s"] / h - whole) * h
    per_sample = int(round(sample_s / h))
    skipped = int(round(start_s / sample_s))
    late = int(round(record_delay_s / h))
    n_samples = int(round(duration_s / sample_s)) + 1 + skipped
    commands = [0.0] * (whole + 2)
    set_points = [reference(i * sample_s) for i in range(n_samples)]
    # the friction's sign is smoothed over 0.1 mm/s, or over the velocity one loop step of
    # the friction would change where that is more (within it the explicit friction would
    # overshoot zero velocity in one step)
    velocity_per_V = _plant_rk4(0.0, 0.0, 1.0, a0, a1, b, h)[1]
    band_mm_s = max(0.1, friction_N / servo["force_constant_N_per_V"] * abs(velocity_per_V))
    x1, x2, integral, previous = set_points[0], 0.0, 0.0, 0.0
    history = [x1] * (late + 1)  # the position at the last late + 1 loop steps
    positions = [x1]
    for k in range((n_samples - 1) * per_sample):
        t = k * h
        sample, within = divmod(k, per_sample)
        error = (set_points[sample] + (set_points[min(sample + 1, n_samples - 1)]
                                       - set_points[sample]) * within / per_sample - x1)
        if servo["controller"] == "npid":
            error *= math.cosh(servo["ko_per_mm"] * min(abs(error), servo["e_max_mm"]))
        integral += 0.5 * (error + previous) * h
        output = (servo["kp_V_per_mm"] * error + servo["ki_V_per_mm_s"] * integral
                  + servo["kd_V_s_per_mm"] * (error - previous) / h)
        previous = error
        commands = commands[1:] + [output]
        force = (force_N(t) if force_N else 0.0) - damping_N_s_per_mm * x2
        if x2 != 0.0:
            force -= friction_N * max(-1.0, min(1.0, x2 / band_mm_s))
        force_V = force / servo["force_constant_N_per_V"]
        if early_s > 0.0:
            x1, x2 = _plant_rk4(x1, x2, commands[-whole - 2] + force_V, a0, a1, b, early_s)
        x1, x2 = _plant_rk4(x1, x2, commands[-whole - 1] + force_V, a0, a1, b, h - early_s)
        history = history[1:] + [x1]
        if (k + 1) % per_sample == 0:
            positions.append(history[0])
    time_s = np.arange(n_samples - skipped) * sample_s
    return time_s, np.array(set_points[skipped:]), np.array(positions[skipped:])


def _encoder_um(rng, size):
    """White plus AR(1) coloured noise (µm)."""
    return (null_noise_um(rng, size, f"ar{COLOURED_POLE}", COLOURED_NOISE_UM)
            + rng.normal(0.0, WHITE_NOISE_UM, size))


def noise_um(size, seed):
    """White plus AR(1) coloured noise (µm), seeded."""
    return _encoder_um(np.random.default_rng(seed), size)


def _drift_um(rng, size):
    """Encoder noise plus a slow drift (thermal growth): 0.5-2 µm over the record, bent,
    about a zero mean over the whole record, so a steady offset of up to about 0.2 µm is
    left over the samples compared after the start-up: the measurement's own offset, which
    a drifting measurement cannot tell from a constant force (not to be named)."""
    phase = np.linspace(-1.0, 1.0, size)
    return (_encoder_um(rng, size) + rng.uniform(0.5, 2.0) * rng.choice((-1, 1)) * phase
            + rng.uniform(-0.5, 0.5) * (phase**2 - np.mean(phase**2)))


def _spikes_um(rng, size):
    """Encoder noise plus three single-sample spikes of 5-20 µm (encoder or transfer glitches)."""
    values = _encoder_um(rng, size)
    spikes = rng.choice(size, 3, replace=False)
    values[spikes] += rng.uniform(5.0, 20.0, 3) * rng.choice((-1, 1), 3)
    return values


def spike_indices(size, seed):
    """Where :func:`_spikes_um` put its spikes for ``seed`` (sorted sample indices)."""
    rng = np.random.default_rng(seed)
    _encoder_um(rng, size)
    return np.sort(rng.choice(size, 3, replace=False))


QUANTUM_UM = 0.1  # the encoder's resolution of the quantised null
# name -> (noise (µm) from (rng, size), resolution (µm) actual_mm is rounded to, or None)
NOISE_FAMILIES = {
    "white 0.3 um": (lambda rng, size: null_noise_um(rng, size, "white", 0.3), None),
    "AR(1) rho 0.5": (lambda rng, size: null_noise_um(rng, size, "ar0.5", 0.3), None),
    "AR(1) rho 0.95": (lambda rng, size: null_noise_um(rng, size, "ar0.95", 0.3), None),
    "Student-t nu 3": (lambda rng, size: null_noise_um(rng, size, "t3", 0.3), None),
    "quantised 0.1 um": (lambda rng, size: rng.normal(0.0, 0.03, size), QUANTUM_UM),
    "drifting": (_drift_um, None),
    "spikes": (_spikes_um, None),
}


def family_noise(family, size, seed):
    """(noise (µm), resolution (µm) or None) of a null family, seeded."""
    draw, resolution_um = NOISE_FAMILIES[family]
    return draw(np.random.default_rng(seed), size), resolution_um


def write_tracking_case(folder, trajectory, seed, force_N=None, axis=AXIS, family=None):
    """Write (time, reference, position) plus seeded noise as a case; ``force_N`` (array)
    is written as the known disturbance_N column. ``family`` names a null's noise
    (:data:`NOISE_FAMILIES`; default white 0.1 µm + AR(1) 0.3 µm, :func:`noise_um`)."""
    time_s, reference_mm, position_mm = trajectory
    if family is None:
        noise, resolution_um = noise_um(time_s.size, seed), None
    else:
        noise, resolution_um = family_noise(family, time_s.size, seed)
    actual_mm = position_mm + noise * 1e-3
    if resolution_um:
        actual_mm = np.round(actual_mm * 1e3 / resolution_um) * resolution_um * 1e-3
    columns = {"time_s": time_s, "reference_mm": reference_mm, "actual_mm": actual_mm}
    if force_N is not None:
        columns["disturbance_N"] = force_N
    return write_case(folder, axis, tracking=columns)


def sine(amplitude_mm, frequency_hz):
    return lambda t: amplitude_mm * math.sin(2 * math.pi * frequency_hz * t)


def two_sines(t):
    """A reference exciting the plant: 10 mm at 0.5 Hz plus 0.3 mm at 7 Hz."""
    return 10.0 * math.sin(math.pi * t) + 0.3 * math.sin(2 * math.pi * 7.0 * t)
