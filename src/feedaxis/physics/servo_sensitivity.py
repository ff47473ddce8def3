"""Forward sensitivities of the servo loop: d position / d parameters from one simulation.

The loop of :func:`.servo.run_loop` is a discrete-time recursion z⁺ = f(z, u; c) in the
coefficient vector c (:func:`.servo.loop_coefficients`). Differentiating each of its lines
gives the tangent recursion dz⁺/dθ = ∂f/∂z · dz/dθ + ∂f/∂c · dc/dθ, stepped beside the loop
itself (forward mode): one pass yields the positions and their derivatives with respect to
every parameter θ, where finite differences need one more simulation per parameter.

- :func:`coefficient_jacobian`: dc/dθ exactly. The plant's entries are functions of the
  zero-order-hold exponentials; their derivatives come from the block exponential
  d e^{Mτ}/dθ = the upper right block of exp([[M, E], [0, M]]·τ), E = dM/dθ (Van Loan,
  "Computing integrals involving the matrix exponential", IEEE Trans. Automatic Control 23
  (1978), Theorem 1), and from d e^{Mτ}/dτ = M·e^{Mτ} for the delay's fraction.
- :func:`run_loop_tangent`: :func:`.servo.run_loop`'s lines, each followed by its derivative
  (its positions equal run_loop's bitwise, its derivatives compiled with fused
  multiply-adds: :func:`compiled_tangent`, tests/physics/test_sensitivity.py).

The friction's sign is a clipped ramp and the NPID gain is held beyond e_max: both are
differentiated piecewise (the side the value is on), as finite differences see them away
from the kinks. The integer part of the delay (whole loop steps) is held: the derivative in
``delay_s`` is the one within its step.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from .servo import (DECAY_UNDERFLOW, FRICTION_SMOOTHING_MM_S, discrete_plant, expm,
                    forces_V, friction_V, loop_coefficients, npid_gain, resists, step_counts,
                    stribeck_V, with_compiled_callees)
from .threads import one_blas_thread

COEFFICIENTS = 27  # the length of loop_coefficients' vector
# the indices in loop_coefficients' vector
TRANSITION, LATE, EARLY = slice(0, 4), slice(4, 6), slice(6, 8)
KP, KI, KD, KO, E_MAX, NONLINEAR = 8, 9, 10, 11, 12, 13
FRICTION, DAMPING = 14, 15
CASCADE, KP_PER_S, KV, KV_TN, FEEDFORWARD = 18, 19, 20, 21, 22
COULOMB, STATIC, STRIBECK_VELOCITY, SMOOTHING = 23, 24, 25, 26
# the parameters :func:`coefficient_jacobian` differentiates
PLANT = ("plant_gain_mm_per_Vs2", "plant_damping_per_s", "plant_stiffness_per_s2", "delay_s")
PER_NEWTON = {"friction_N": FRICTION, "damping_N_s_per_mm": DAMPING, "coulomb_N": COULOMB,
              "static_N": STATIC}
GAINS = {"kp_V_per_mm": KP, "ki_V_per_mm_s": KI, "kd_V_s_per_mm": KD, "ko_per_mm": KO,
         "e_max_mm": E_MAX, "kp_per_s": KP_PER_S, "velocity_feedforward": FEEDFORWARD,
         "stribeck_velocity_mm_s": STRIBECK_VELOCITY}
PARAMETERS = (*PLANT, *PER_NEWTON, *GAINS, "kv_V_s_per_mm", "tn_s", "force_N")


def _augmented(params):
    """M of the zero-order hold (:func:`.servo._zoh`), unit input column."""
    return np.array([[0.0, 1.0, 0.0],
                     [-params.plant_stiffness_per_s2, -params.plant_damping_per_s, 1.0],
                     [0.0, 0.0, 0.0]])


def _exp_and_derivative(matrix, direction, duration_s):
    """(e^{M·τ}, its derivative along E: M → M + εE), from one 6x6 block exponential."""
    size = len(matrix)
    block = np.zeros((2 * size, 2 * size))
    block[:size, :size] = block[size:, size:] = matrix
    block[:size, size:] = direction
    full = expm(block * duration_s)
    return full[:size, :size], full[:size, size:]


def _plant_derivatives(params, name):
    """d(transition (2x2), late (2,), early (2,))/d``name`` for one plant parameter, as
    :func:`.servo.discrete_plant` composes them: transition = Φ_L·Φ_E, late = b·G_L,
    early = Φ_L·b·G_E with (Φ, G) blocks of e^{M·τ} at τ_L = (1 − f)·h and τ_E = f·h."""
    h = params.time_step_s
    fraction = min(max(params.delay_s / h - params.delay_steps, 0.0), 1.0)
    matrix, gain = _augmented(params), params.plant_gain_mm_per_Vs2
    spans = ((1.0 - fraction) * h, fraction * h)
    if name == "plant_gain_mm_per_Vs2":
        _, late, early = discrete_plant(params)
        return np.zeros((2, 2)), late / gain, early / gain
    if name == "delay_s":  # dτ_L/dτ = −1, dτ_E/dτ = +1 (within the step)
        exps = [expm(matrix * span) for span in spans]
        derivs = [sign * matrix @ e for sign, e in zip((-1.0, 1.0), exps)]
    else:
        direction = np.zeros((3, 3))
        direction[1, 1 if name == "plant_damping_per_s" else 0] = -1.0
        pairs = [_exp_and_derivative(matrix, direction, span) for span in spans]
        exps, derivs = [p[0] for p in pairs], [p[1] for p in pairs]
    (late_exp, early_exp), (d_late, d_early) = exps, derivs
    d_transition = d_late[:2, :2] @ early_exp[:2, :2] + late_exp[:2, :2] @ d_early[:2, :2]
    d_early_column = gain * (d_late[:2, :2] @ early_exp[:2, 2]
                             + late_exp[:2, :2] @ d_early[:2, 2])
    return d_transition, gain * d_late[:2, 2], d_early_column


def coefficient_jacobian(params, names):
    """dc/dθ ((len(names), 27)) of :func:`.servo.loop_coefficients` for the parameters
    ``names`` (of :data:`PARAMETERS`), and d(force as a command, V)/dθ (len(names),):
    ``force_N`` enters as force_N / force_constant over every interval."""
    unknown = [name for name in names if name not in PARAMETERS]
    if unknown:
        raise ValueError(f"no sensitivity for {', '.join(unknown)}")
    coefficients = loop_coefficients(params)
    volts_per_N = 1.0 / params.force_constant_N_per_V
    jacobian = np.zeros((len(names), COEFFICIENTS))
    force = np.zeros(len(names))
    peak_V = (params.friction_N + max(params.coulomb_N, params.static_N)) * volts_per_N
    velocity_per_V = coefficients[LATE][1] + coefficients[EARLY][1]
    widened = peak_V * abs(velocity_per_V) > FRICTION_SMOOTHING_MM_S  # smoothing's branch
    cascade = params.controller == "cascade"
    for row, name in enumerate(names):
        d = jacobian[row]
        d_peak_V = 0.0
        if name in PLANT:
            d_transition, d_late, d_early = _plant_derivatives(params, name)
            d[TRANSITION], d[LATE], d[EARLY] = d_transition.ravel(), d_late, d_early
        elif name in PER_NEWTON:
            d[PER_NEWTON[name]] = volts_per_N
            # the peak friction friction_N + max(coulomb_N, static_N) sets the smoothing
            larger = "coulomb_N" if params.coulomb_N >= params.static_N else "static_N"
            d_peak_V = volts_per_N if name in ("friction_N", larger) else 0.0
        elif name in GAINS:
            d[GAINS[name]] = 1.0
        elif name == "kv_V_s_per_mm" and cascade:
            d[KV] = 1.0
            d[KV_TN] = 1.0 / params.tn_s if params.tn_s > 0.0 else 0.0
        elif name == "tn_s" and cascade and params.tn_s > 0.0:
            d[KV_TN] = -params.kv_V_s_per_mm / params.tn_s ** 2
        elif name == "force_N":
            force[row] = volts_per_N
        if widened:  # smoothing = peak_V·|late₂ + early₂|
            d_velocity = d[LATE][1] + d[EARLY][1]
            d[SMOOTHING] = (d_peak_V * abs(velocity_per_V)
                            + peak_V * math.copysign(1.0, velocity_per_V) * d_velocity)
    return jacobian, force


def friction_tangent(velocity_mm_s, coulomb_V, damping_V_s_per_mm, rise_coulomb_V, static_V,
                     stribeck_velocity_mm_s, smoothing_mm_s, rising):
    """The partial derivatives of :func:`.servo.friction_V` with respect to its seven
    arguments, in their order (floats; the clipped sign differentiated on its side).

    Also where every friction force is 0 (a fit's start, where friction_V skips them): the
    friction is linear in each force there, so its column is the sign's (times the Stribeck
    decay for the rise), not 0, or a fit started at 0 never moves them. ``rising`` false
    (no rise at rest acts and none of its parameters moves) leaves the decay at 0: every
    term it enters is then multiplied by zeros. The decay is evaluated once, for the
    magnitude (:func:`.servo.stribeck_V`'s expression, 0 where it underflows) and the
    derivatives alike.
    """
    ramp = velocity_mm_s / smoothing_mm_s
    sign = min(max(ramp, -1.0), 1.0)
    ratio = velocity_mm_s / stribeck_velocity_mm_s
    square = ratio * ratio
    decay = 0.0 if not rising or square > DECAY_UNDERFLOW else math.exp(-square)
    magnitude = coulomb_V + (rise_coulomb_V + (static_V - rise_coulomb_V) * decay)
    slope = (static_V - rise_coulomb_V) * decay * -2.0 * ratio  # d stribeck_V / d ratio
    d_velocity = damping_V_s_per_mm + slope / stribeck_velocity_mm_s * sign
    d_stribeck = -slope * ratio / stribeck_velocity_mm_s * sign
    d_smoothing = 0.0
    if -1.0 < ramp < 1.0:
        d_velocity += magnitude / smoothing_mm_s
        d_smoothing = -magnitude * ramp / smoothing_mm_s
    return (d_velocity, sign, velocity_mm_s, (1.0 - decay) * sign, decay * sign, d_stribeck,
            d_smoothing)


def npid_tangent(error_mm, ko_per_mm, e_max_mm):
    """(dK/de, dK/dKO, dK/de_max) of :func:`.servo.npid_gain` K = cosh(KO·min(|e|, e_max))."""
    held = abs(error_mm) >= e_max_mm
    level = e_max_mm if held else abs(error_mm)
    rate = math.sinh(ko_per_mm * level)
    d_level = 0.0 if held else math.copysign(1.0, error_mm)
    return rate * ko_per_mm * d_level, rate * level, rate * ko_per_mm if held else 0.0


def pid_step(error, integral, previous, kp, ki, kd, dt):
    """(integral, derivative, command) after a step of :func:`.servo.run_loop`'s PID (its
    lines): the tangent kernels take the loop's own values from here, compiled without the
    fused multiply-adds their derivatives are compiled with (:func:`compiled_tangent`)."""
    integral += 0.5 * (error + previous) * dt
    derivative = (error - previous) / dt
    return integral, derivative, kp * error + ki * integral + kd * derivative


def cascade_step(error, slope_mm_s, x2, integral, previous, kp_per_s, feedforward, kv, kv_tn,
                 dt):
    """(bracket, integral, command) after a step of :func:`.servo.run_loop`'s cascade (its
    lines, as :func:`pid_step`)."""
    bracket = kp_per_s * error + feedforward * slope_mm_s - x2
    integral += 0.5 * (bracket + previous) * dt
    return bracket, integral, kv * bracket + kv_tn * integral


def plant_step(x1, x2, u_late, u_early, plant):
    """(position, velocity) after a step of :func:`.servo.run_loop`'s plant (its lines, as
    :func:`pid_step`); ``plant`` the coefficients' first eight (transition, late, early)."""
    a11, a12, a21, a22, late1, late2, early1, early2 = plant
    return (a11 * x1 + a12 * x2 + late1 * u_late + early1 * u_early,
            a21 * x1 + a22 * x2 + late2 * u_late + early2 * u_early)


def run_loop_tangent(coefficients, d_coefficients, steps, references_mm, disturbances_V,
                     d_disturbance_V, state, buffer, d_state, d_buffer, positions_mm,
                     d_positions_mm):
    """:func:`.servo.run_loop` with the derivatives of its state stepped beside it.

    ``d_coefficients`` (27 x p: :func:`coefficient_jacobian` transposed, a parameter's
    derivatives along a row for the inner loops) and ``d_disturbance_V`` (p,) its force;
    ``d_state`` (4 x p: position, velocity, integral, previous) and ``d_buffer`` (delay line
    x p) start at 0 for a loop started from given values; ``d_positions_mm`` (p x samples)
    receives d position / dθ at each sample, a parameter's along a row. Each block below is
    one line of run_loop followed by its derivative. Where no friction force acts and no
    parameter moves one (``frictional`` false: a plant's fit without friction), the
    friction's derivative is its viscous term alone, its other terms products with zeros,
    and its tangent is not evaluated (an exponential per step: 1.7x the pass of the four
    plant parameters).
    """
    a11, a12, a21, a22, late1, late2, early1, early2 = coefficients[0:8]
    plant = (a11, a12, a21, a22, late1, late2, early1, early2)
    kp, ki, kd, ko, e_max, nonlinear = coefficients[8:14]
    dt, delay = coefficients[16], coefficients[17]
    cascade, kp_per_s, kv, kv_tn, feedforward = coefficients[18:23]
    coulomb_V, damping_V_s_per_mm = coefficients[14], coefficients[15]
    rise_V, static_V, stribeck_mm_s, smoothing_mm_s = coefficients[23:27]
    dc = d_coefficients
    p = dc.shape[1]
    resisted = resists(coulomb_V, damping_V_s_per_mm, rise_V, static_V)
    frictional = coulomb_V != 0.0 or rise_V != 0.0 or static_V != 0.0
    rising = rise_V != 0.0 or static_V != 0.0
    tuned = False  # a PID gain among the parameters (else their terms multiply zeros)
    for j in range(p):
        for row in (KP, KI, KD):
            tuned = tuned or dc[row, j] != 0.0
        for row in (FRICTION, DAMPING, COULOMB, STATIC, STRIBECK_VELOCITY, SMOOTHING):
            frictional = frictional or dc[row, j] != 0.0
        for row in (COULOMB, STATIC, STRIBECK_VELOCITY):
            rising = rising or dc[row, j] != 0.0
    f_v, f_c, f_d, f_r, f_s, f_vs, f_w = damping_V_s_per_mm, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    x1, x2, integral, previous, start_mm = state[0], state[1], state[2], state[3], state[4]
    head = int(state[5])
    size = len(buffer)
    shift = int(delay)
    dx1, dx2, d_integral, d_previous = d_state[0], d_state[1], d_state[2], d_state[3]
    d_command = np.empty(p)
    for i in range(len(steps)):
        n_steps = steps[i]
        end_mm = references_mm[i]
        force_V = disturbances_V[i]
        slope_mm_s = (end_mm - start_mm) / (n_steps * dt) if n_steps > 0 else 0.0
        for k in range(1, n_steps + 1):
            error = start_mm + (end_mm - start_mm) * (k - 1) / n_steps - x1
            if cascade != 0.0:
                bracket, integral, command = cascade_step(
                    error, slope_mm_s, x2, integral, previous, kp_per_s, feedforward, kv, kv_tn,
                    dt)
                for j in range(p):
                    d_bracket = (dc[KP_PER_S, j] * error - kp_per_s * dx1[j]
                                 + dc[FEEDFORWARD, j] * slope_mm_s - dx2[j])
                    d_integral[j] += 0.5 * (d_bracket + d_previous[j]) * dt
                    d_previous[j] = d_bracket
                previous = bracket
                for j in range(p):
                    d_command[j] = (dc[KV, j] * bracket + kv * d_previous[j]
                                    + dc[KV_TN, j] * integral + kv_tn * d_integral[j])
            else:
                raw = error
                for j in range(p):
                    d_command[j] = -dx1[j]  # d error, before the gain
                if nonlinear != 0.0:
                    gain = npid_gain(raw, ko, e_max)
                    d_gain_e, d_gain_ko, d_gain_max = npid_tangent(raw, ko, e_max)
                    error = raw * gain
                    for j in range(p):
                        d_command[j] = (d_command[j] * (gain + raw * d_gain_e) + raw * (
                            d_gain_ko * dc[KO, j] + d_gain_max * dc[E_MAX, j]))
                integral, derivative, command = pid_step(error, integral, previous, kp, ki, kd,
                                                         dt)
                for j in range(p):
                    d_error = d_command[j]
                    d_integral[j] += 0.5 * (d_error + d_previous[j]) * dt
                    d_derivative = (d_error - d_previous[j]) / dt
                    d_previous[j] = d_error
                    if tuned:
                        d_command[j] = (dc[KP, j] * error + kp * d_error + dc[KI, j] * integral
                                        + ki * d_integral[j] + dc[KD, j] * derivative
                                        + kd * d_derivative)
                    else:
                        d_command[j] = kp * d_error + ki * d_integral[j] + kd * d_derivative
                previous = error
            buffer[head] = command
            late = head - shift
            if late < 0:
                late += size
            early = late - 1 if late > 0 else size - 1
            command_late = buffer[late]
            command_early = buffer[early]
            force = force_V
            if resisted:
                force = force_V - friction_V(x2, coulomb_V, damping_V_s_per_mm, rise_V,
                                             static_V, stribeck_mm_s, smoothing_mm_s)
            if frictional:
                f_v, f_c, f_d, f_r, f_s, f_vs, f_w = friction_tangent(
                    x2, coulomb_V, damping_V_s_per_mm, rise_V, static_V, stribeck_mm_s,
                    smoothing_mm_s, rising)
            u_late = command_late + force
            u_early = command_early + force
            for j in range(p):
                d_buffer[head, j] = d_command[j]
                if frictional:
                    d_force = d_disturbance_V[j] - (
                        f_v * dx2[j] + f_c * dc[FRICTION, j] + f_d * dc[DAMPING, j]
                        + f_r * dc[COULOMB, j] + f_s * dc[STATIC, j]
                        + f_vs * dc[STRIBECK_VELOCITY, j] + f_w * dc[SMOOTHING, j])
                elif resisted:
                    d_force = d_disturbance_V[j] - f_v * dx2[j]
                else:
                    d_force = d_disturbance_V[j]
                du_late = d_buffer[late, j] + d_force
                du_early = d_buffer[early, j] + d_force
                d1 = (dc[0, j] * x1 + a11 * dx1[j] + dc[1, j] * x2 + a12 * dx2[j]
                      + dc[4, j] * u_late + late1 * du_late + dc[6, j] * u_early
                      + early1 * du_early)
                d2 = (dc[2, j] * x1 + a21 * dx1[j] + dc[3, j] * x2 + a22 * dx2[j]
                      + dc[5, j] * u_late + late2 * du_late + dc[7, j] * u_early
                      + early2 * du_early)
                dx1[j], dx2[j] = d1, d2
            head = head + 1 if head + 1 < size else 0
            x1, x2 = plant_step(x1, x2, u_late, u_early, plant)
        if n_steps > 0:
            start_mm = end_mm
        positions_mm[i] = x1
        for j in range(p):
            d_positions_mm[j, i] = dx1[j]
    state[0], state[1], state[2], state[3], state[4], state[5] = (
        x1, x2, integral, previous, start_mm, float(head))


def run_loop_tangent_pid(coefficients, d_coefficients, steps, references_mm, disturbances_V,
                         d_disturbance_V, state, buffer, d_state, d_buffer, positions_mm,
                         d_positions_mm):
    """:func:`run_loop_tangent` where the loop is a PID without friction and no PID gain is
    among the parameters (the plant's fit: :func:`plain_pid`): the same arguments, the same
    lines, with no branch in its inner loops, the controller's derivatives written straight
    into the delay line and each parameter's state in its own array (the plant's four
    parameters on 5·10⁶ loop steps: 205 -> 148 ms, medians of 7 side by side; the same
    positions to the bit, the same columns within 1e-12 where the two kernels fuse their
    multiply-adds otherwise: tests/physics/test_sensitivity.py)."""
    a11, a12, a21, a22, late1, late2, early1, early2 = coefficients[0:8]
    plant = (a11, a12, a21, a22, late1, late2, early1, early2)
    kp, ki, kd = coefficients[KP], coefficients[KI], coefficients[KD]
    dt, delay = coefficients[16], coefficients[17]
    c0, c1, c2, c3 = (d_coefficients[0].copy(), d_coefficients[1].copy(),
                      d_coefficients[2].copy(), d_coefficients[3].copy())
    c4, c5, c6, c7 = (d_coefficients[4].copy(), d_coefficients[5].copy(),
                      d_coefficients[6].copy(), d_coefficients[7].copy())
    p = d_coefficients.shape[1]
    x1, x2, integral, previous, start_mm = state[0], state[1], state[2], state[3], state[4]
    head = int(state[5])
    size = len(buffer)
    shift = int(delay)
    dx1, dx2 = d_state[0].copy(), d_state[1].copy()
    d_integral, d_previous = d_state[2].copy(), d_state[3].copy()
    for i in range(len(steps)):
        n_steps = steps[i]
        end_mm = references_mm[i]
        force_V = disturbances_V[i]
        for k in range(1, n_steps + 1):
            error = start_mm + (end_mm - start_mm) * (k - 1) / n_steps - x1
            integral, _, command = pid_step(error, integral, previous, kp, ki, kd, dt)
            previous = error
            buffer[head] = command
            late = head - shift
            if late < 0:
                late += size
            early = late - 1 if late > 0 else size - 1
            u_late = buffer[late] + force_V
            u_early = buffer[early] + force_V
            d_command, d_late, d_early = d_buffer[head], d_buffer[late], d_buffer[early]
            for j in range(p):
                d_error = -dx1[j]
                d_integral[j] += 0.5 * (d_error + d_previous[j]) * dt
                d_derivative = (d_error - d_previous[j]) / dt
                d_previous[j] = d_error
                d_command[j] = kp * d_error + ki * d_integral[j] + kd * d_derivative
            for j in range(p):
                du_late = d_late[j] + d_disturbance_V[j]
                du_early = d_early[j] + d_disturbance_V[j]
                d1 = (c0[j] * x1 + a11 * dx1[j] + c1[j] * x2 + a12 * dx2[j]
                      + c4[j] * u_late + late1 * du_late + c6[j] * u_early
                      + early1 * du_early)
                d2 = (c2[j] * x1 + a21 * dx1[j] + c3[j] * x2 + a22 * dx2[j]
                      + c5[j] * u_late + late2 * du_late + c7[j] * u_early
                      + early2 * du_early)
                dx1[j], dx2[j] = d1, d2
            head = head + 1 if head + 1 < size else 0
            x1, x2 = plant_step(x1, x2, u_late, u_early, plant)
        if n_steps > 0:
            start_mm = end_mm
        positions_mm[i] = x1
        for j in range(p):
            d_positions_mm[j, i] = dx1[j]
    d_state[0, :], d_state[1, :], d_state[2, :], d_state[3, :] = (dx1, dx2, d_integral,
                                                                  d_previous)
    state[0], state[1], state[2], state[3], state[4], state[5] = (
        x1, x2, integral, previous, start_mm, float(head))


def plain_pid(coefficients, names):
    """Whether :func:`run_loop_tangent_pid` steps the pass of the loop of ``coefficients``
    (:func:`.servo.loop_coefficients`): a PID (not NPID, not a cascade) without friction,
    differentiated in the plant's parameters and the constant force only."""
    return (coefficients[NONLINEAR] == 0.0 and coefficients[CASCADE] == 0.0
            and not resists(coefficients[FRICTION], coefficients[DAMPING],
                            coefficients[COULOMB], coefficients[STATIC])
            and set(names) <= {*PLANT, "force_N"})


@lru_cache(maxsize=1)
def compiled_pid_tangent():
    """:func:`run_loop_tangent_pid` compiled by numba's JIT (cached on disk), as
    :func:`compiled_tangent`."""
    return _compiled(numba_ready_tangent(run_loop_tangent_pid))


@lru_cache(maxsize=1)
def compiled_tangent():
    """:func:`run_loop_tangent` compiled by numba's JIT (cached on disk), its calls of the
    loop's friction and NPID gain and their tangents bound to compiled copies.

    The derivatives' multiply-adds are fused (LLVM's contraction, numba's fastmath
    "contract": 0.84x the time of the PID's pass of the plant on 5·10⁶ loop steps, 0.92x
    the friction screens' pass; columns within 4e-15 of their largest value), the loop's
    own values not: they come from :func:`pid_step`, :func:`cascade_step`,
    :func:`plant_step` and :func:`.servo.friction_V`, compiled without (explicitly: a
    callee otherwise takes its caller's fastmath), so the positions are
    :func:`.servo.run_loop`'s to the bit, as the fit's residual and the FMUs take them."""
    return _compiled(numba_ready_tangent(run_loop_tangent))


def numba_ready_tangent(kernel):
    """``kernel`` (:func:`run_loop_tangent` or :func:`run_loop_tangent_pid`) with its calls
    bound to copies compiled by numba without fused multiply-adds
    (:func:`.servo.with_compiled_callees`)."""
    import numba

    return with_compiled_callees(
        numba, kernel, npid_gain, npid_tangent, resists,
        with_compiled_callees(numba, friction_V, stribeck_V), friction_tangent, pid_step,
        cascade_step, plant_step, fastmath=False)


def _compiled(kernel):
    """``kernel`` (:func:`numba_ready_tangent`'s) compiled with fused multiply-adds, cached on
    disk (:func:`.numba_cache.cached_njit`)."""
    import numba

    from .numba_cache import cached_njit

    return cached_njit(numba, kernel, nogil=True, fastmath={"contract"})


@one_blas_thread
def simulate_sensitivity(params, names, time_s, reference_mm, disturbance_N=None, counts=None):
    """(position_mm (samples,), d position_mm / d``names`` (samples x len(names))) at each
    sample of a tracking record, as :func:`.servo.simulate` steps it, from one pass.

    The derivatives are stored column by column (Fortran order), as the fit's trust region
    takes them: its column sums and its scaled copies run down contiguous columns."""
    reference_mm = np.ascontiguousarray(reference_mm, dtype=float)
    counts = step_counts(time_s, params.time_step_s) if counts is None else counts
    d_coefficients, d_force = coefficient_jacobian(params, names)
    state = np.array([reference_mm[0], 0.0, 0.0, 0.0, reference_mm[0], 0.0])
    positions_mm = np.empty_like(reference_mm)
    d_positions = np.zeros((len(names), reference_mm.size))
    coefficients = loop_coefficients(params)
    kernel = compiled_pid_tangent() if plain_pid(coefficients, names) else compiled_tangent()
    kernel(coefficients, np.ascontiguousarray(d_coefficients.T), counts, reference_mm,
           forces_V(params, disturbance_N, reference_mm.size), d_force, state,
           np.zeros(params.buffer_size), np.zeros((4, len(names))),
           np.zeros((params.buffer_size, len(names))), positions_mm, d_positions)
    return positions_mm, d_positions.T

