"""Position servo of a ball-screw drive: PID or NPID (Anang et al. 2017 Eq. 1-8) or a drive's cascade.

Plant (Eq. 1, Googol XY table, x axis): G(s) = 78020 / (s² + 163 s + 193.3), command in V,
position in mm, with a 1.2 ms transport delay on the command. Controller (Eq. 2, 6):
C(s) = K_P + K_I/s + K_D·s acting on the tracking error e = reference - position (mm).
NPID (Eq. 7-8) puts the nonlinear gain K(e) = (exp(KO·e) + exp(-KO·e)) / 2 = cosh(KO·e)
in front of the PID, held at K(e_max) for |e| > e_max. The cascade of industrial drives
(case format 1.2): a proportional position loop commanding a velocity, around a velocity
loop on the measured velocity, with an optional velocity feed-forward and integral action,

    u = kv·(kp·(r − x) + vff·dr/dt − dx/dt) [+ (kv / tn)·∫(the bracket) dt]   (V)

r the reference, x the position (mm), dx/dt the plant's velocity at the step's start.

The loop runs at a fixed internal step: the plant is discretised exactly for a command held
over each step (zero-order hold), the integral by the trapezoidal rule and the derivative
by a backward difference; the delay is a shift by whole steps. An axial force enters at the
plant input as an equivalent command F / force_constant, as the case format (docs/case-format.md) states (the
paper gives no force scaling; see :class:`ServoParams`): the known disturbance, and the
friction of the guideways and the nut, a Coulomb force ``friction_N`` opposing the velocity
(smoothed linearly over |v| < ``FRICTION_SMOOTHING_MM_S``, wider where a loop step could
not resolve it: :func:`friction_smoothing_mm_s`) plus a viscous force
``damping_N_s_per_mm``·v, both from the velocity at the start of the step, and a Stribeck
rise of the friction at rest (``coulomb_N`` + (``static_N`` − ``coulomb_N``)·exp(−(v/v_s)²),
Armstrong-Hélouvry, Dupont & Canudas de Wit, "A survey of models, analysis tools and
compensation methods for the control of machines with friction", Automatica 30 (1994),
Eq. 2 with δ = 2), smoothed as the Coulomb force; a constant axial force ``force_N`` (the
weight on an inclined axis, a counterbalance) adds to the known disturbance.

One kernel, :func:`run_loop`, advances the loop for the FMU (:class:`Servo`) and for the fit
(:func:`simulate`, the same function compiled by numba's JIT): they agree to rounding. The
NpidServo FMU carries it compiled ahead of time (feedaxis.kernel_build; loaded by
:func:`shipped_loop`), so every controller mode costs the same there. Without that module
:class:`Servo` runs it in Python, and advances a linear loop (PID without Coulomb friction)
over a whole communication step with one matrix instead (:func:`loop_propagator`, built by
running the kernel on unit vectors).
"""
from __future__ import annotations

import math
import types
from dataclasses import dataclass, fields
from functools import lru_cache

import numpy as np

from .checks import (ParameterError, require_finite, require_non_negative, require_positive,
                     require_representable)
from .kernel import shipped_kernel
from .threads import one_blas_thread

FRICTION_SMOOTHING_MM_S = 0.1
# exp(−x) rounds to 0 in double precision beyond x = 745.14 (under half the least subnormal):
# the Stribeck decay exp(−(v/v_s)²) is 0 there without the call, whose underflow path costs
# three times an ordinary exponential (a third of a servo trace's loop steps, at v_s = 1 mm/s)
DECAY_UNDERFLOW = 746.0
STATE_SIZE = 6  # position_mm, velocity_mm_s, integral, previous (controller input),
# reference_mm, head
CONTROLLERS = ("pid", "npid", "cascade")
# The loop steps through every interval of a record, so its cost is the record's span over
# the loop step, whatever the samples: a record may ask for at most this many steps between
# two samples (10 s at 0.1 ms) and in all (about 1.5 s of the compiled loop per simulation).
MAX_INTERVAL_STEPS = 10**5
MAX_LOOP_STEPS = 10**8
MAX_POSITION_MM = 1e5  # a simulated position beyond any axis (docs/case-format.md): the loop ran away
# the plant a fit may identify (servo_plant's bounds): gain mm/(V.s2), damping 1/s,
# stiffness 1/s2, delay s
PLANT_BOUNDS = {"plant_gain_mm_per_Vs2": (1e-1, 1e7), "plant_damping_per_s": (0.0, 1e4),
                "plant_stiffness_per_s2": (0.0, 1e5), "delay_s": (0.0, 0.02)}
# The delay line holds delay_s / time_step_s commands: 10^6 (8 MB) covers the tracking
# fit's widest case, a 20 ms delay at the shortest loop step a case may have (1e-7 s).
MAX_DELAY_STEPS = 1_000_000
# A linear loop without the compiled kernel advances by a propagator of (delay steps + 7)²
# entries, built by as many runs of the loop: beyond this delay it steps the loop instead.
MAX_PROPAGATOR_DELAY_STEPS = 64


@dataclass(frozen=True)
class ServoParams:
    """Plant, controller and loop timing. Defaults: Anang et al. 2017 Eq. 1, 6, 8.

    ``force_constant_N_per_V`` converts the disturbance force to the equivalent plant
    command; Anang et al. 2017 does not publish it, the default 100 N/V is an assumption.
    """

    controller: str = "pid"
    plant_gain_mm_per_Vs2: float = 78020.0
    plant_damping_per_s: float = 163.0
    plant_stiffness_per_s2: float = 193.3
    delay_s: float = 0.0012
    kp_V_per_mm: float = 0.8998
    ki_V_per_mm_s: float = 0.0006077
    kd_V_s_per_mm: float = 0.005155
    ko_per_mm: float = 6.0
    e_max_mm: float = 0.3
    nonlinear: bool = False
    force_constant_N_per_V: float = 100.0
    time_step_s: float = 1e-4
    friction_N: float = 0.0
    damping_N_s_per_mm: float = 0.0
    kp_per_s: float = 40.0
    kv_V_s_per_mm: float = 0.005
    tn_s: float = 0.0
    velocity_feedforward: float = 0.0
    force_N: float = 0.0
    coulomb_N: float = 0.0
    static_N: float = 0.0
    stribeck_velocity_mm_s: float = 1.0

    def __post_init__(self):
        if self.controller not in CONTROLLERS:
            raise ParameterError(f"must be one of {', '.join(CONTROLLERS)}, got "
                                 f"{self.controller!r}", "controller")
        if self.controller == "cascade" and self.nonlinear:
            raise ParameterError("the NPID gain (nonlinear = true) belongs to a PID, not to a "
                                 "cascade controller", "nonlinear")
        for field in fields(self):
            value = getattr(self, field.name)
            if field.name in ("delay_s", "ki_V_per_mm_s", "kd_V_s_per_mm", "ko_per_mm",
                              "plant_damping_per_s", "plant_stiffness_per_s2", "friction_N",
                              "damping_N_s_per_mm", "tn_s", "coulomb_N", "static_N",
                              "velocity_feedforward"):
                require_non_negative(field.name, value)
            elif field.name == "force_N":
                require_finite(field.name, value)
            elif field.name not in ("nonlinear", "controller"):
                require_positive(field.name, value)
        if not 0.0 <= self.velocity_feedforward <= 1.0:
            raise ParameterError(f"must be 0 to 1, got {self.velocity_feedforward!r}",
                                 "velocity_feedforward")
        if not self.delay_s / self.time_step_s <= MAX_DELAY_STEPS:
            raise ParameterError(
                f"delay_s / time_step_s = {self.delay_s} / {self.time_step_s} s is "
                f"{self.delay_s / self.time_step_s:.3g} internal steps of delay, at most "
                f"{MAX_DELAY_STEPS} (raise time_step_s or shorten delay_s)", "time_step_s")

    @property
    def npid(self):
        """Whether the NPID gain acts (controller ``npid``, or ``nonlinear`` on a PID)."""
        return self.controller == "npid" or self.nonlinear

    @property
    def delay_steps(self):
        """Whole internal steps in the transport delay."""
        return int(math.floor(self.delay_s / self.time_step_s + 1e-9))

    @property
    def buffer_size(self):
        """Commands the delay line holds: the whole-step shift plus one for the fraction."""
        return self.delay_steps + 2


def npid_gain(error_mm, ko_per_mm, e_max_mm):
    """K(e) = cosh(KO·e), held at K(e_max) beyond ±e_max (Anang et al. 2017 Eq. 8), for a float e."""
    return math.cosh(ko_per_mm * min(abs(error_mm), e_max_mm))


def expm(matrix):
    """e^M of a small square matrix by scaling and squaring its Taylor series.

    e^M = (e^{M/2^s})^{2^s} with s chosen so that ||M/2^s||_1 <= 1, where the series is
    summed until a term no longer changes the sum (Moler & Van Loan, "Nineteen dubious ways
    to compute the exponential of a matrix, twenty-five years later", SIAM Review 45 (2003),
    methods 1 and 3). The servo needs one 3x3 exponential per loop discretisation; this
    keeps scipy.linalg (0.2 s to import) off the FMU's initialisation. Agrees with
    scipy.linalg.expm to rounding (tests/physics/test_physics.py).
    """
    matrix = np.asarray(matrix, dtype=float)
    norm = np.abs(matrix).sum(axis=0).max()
    squarings = max(0, math.ceil(math.log2(norm))) if norm > 1.0 else 0
    scaled = matrix / 2.0**squarings
    result = term = np.eye(len(matrix))
    for k in range(1, 40):
        term = term @ scaled / k
        total = result + term
        if np.array_equal(total, result):
            break
        result = total
    for _ in range(squarings):
        result = result @ result
    return result


def _zoh(plant, duration_s):
    """(Φ, Γ) = (e^{A·τ}, ∫₀^τ e^{A·s} ds · B) from e^{M·τ}, M = [[A, e₂], [0, 0]] (Van Loan).

    ``plant`` is (a0, a1, b) of ẋ = [[0, 1], [-a0, -a1]] x + [0, b] u. The input column
    is the unit e₂ and Γ is scaled by b afterwards (Γ is linear in B): b·τ would otherwise
    set the number of squarings (7.8 at the defaults) and cost accuracy in Φ.
    """
    stiffness, damping, gain = plant
    augmented = expm(np.array([[0.0, 1.0, 0.0], [-stiffness, -damping, 1.0], [0.0, 0.0, 0.0]])
                     * duration_s)
    return augmented[:2, :2], gain * augmented[:2, 2]


def discrete_plant(params):
    """Exact zero-order-hold discretisation of Eq. 1 with its fractional delay.

    State x = (position_mm, velocity_mm_s); ẋ = [[0, 1], [-a0, -a1]] x + [0, b] u. With the
    delay τ = (d + f)·h (d whole steps, 0 <= f < 1) a command held over each step reaches the
    plant as x⁺ = Φ x + Γ₁ u[k-d-1] + Γ₀ u[k-d] (Åström & Wittenmark, Computer-Controlled
    Systems, 3rd ed., Sec. 2.3, systems with time delay); a force, not delayed, enters with
    Γ = Γ₀ + Γ₁.

    Returns
    -------
    Φ (2x2), Γ₀, Γ₁ (2,) as NumPy arrays.
    """
    h = params.time_step_s
    fraction = params.delay_s / h - params.delay_steps
    fraction = min(max(fraction, 0.0), 1.0)
    plant = (params.plant_stiffness_per_s2, params.plant_damping_per_s,
             params.plant_gain_mm_per_Vs2)
    transition, late = _zoh(plant, (1.0 - fraction) * h)
    if fraction == 0.0:
        return transition, late, np.zeros(2)
    transition_early, early = _zoh(plant, fraction * h)
    return transition @ transition_early, late, transition @ early


def loop_coefficients(params):
    """The flat coefficient vector :func:`run_loop` reads (plant, controller, friction)."""
    with np.errstate(over="ignore", invalid="ignore"):  # checked below
        transition, late, early = discrete_plant(params)
    require_representable("a discrete plant (e^{A·h} and its input columns)",
                          np.abs(np.concatenate((transition.ravel(), late, early))).sum(), False,
                          plant_gain_mm_per_Vs2=params.plant_gain_mm_per_Vs2,
                          plant_damping_per_s=params.plant_damping_per_s,
                          plant_stiffness_per_s2=params.plant_stiffness_per_s2,
                          time_step_s=params.time_step_s)
    volts_per_N = 1.0 / params.force_constant_N_per_V
    require_representable("the command per newton 1 / force_constant (V/N)", volts_per_N,
                          force_constant_N_per_V=params.force_constant_N_per_V)
    friction_V = params.friction_N * volts_per_N
    damping_V_s_per_mm = params.damping_N_s_per_mm * volts_per_N
    coulomb_V, static_V = params.coulomb_N * volts_per_N, params.static_N * volts_per_N
    require_representable("friction forces as commands (V, V·s/mm)",
                          friction_V + damping_V_s_per_mm + coulomb_V + static_V, False,
                          force_constant_N_per_V=params.force_constant_N_per_V,
                          friction_N=params.friction_N,
                          damping_N_s_per_mm=params.damping_N_s_per_mm,
                          coulomb_N=params.coulomb_N, static_N=params.static_N)
    cascade = params.controller == "cascade"
    integral_gain = (params.kv_V_s_per_mm / params.tn_s if cascade and params.tn_s > 0.0
                     else 0.0)
    require_representable("the velocity loop's integral gain kv / tn (V/mm)", integral_gain,
                          False, kv_V_s_per_mm=params.kv_V_s_per_mm, tn_s=params.tn_s)
    smoothing_mm_s = friction_smoothing_mm_s(friction_V + max(coulomb_V, static_V),
                                             late[1] + early[1])
    return np.array([*transition.ravel(), *late, *early, params.kp_V_per_mm,
                     params.ki_V_per_mm_s, params.kd_V_s_per_mm, params.ko_per_mm,
                     params.e_max_mm, float(params.npid), friction_V,
                     damping_V_s_per_mm, params.time_step_s, float(params.delay_steps),
                     float(cascade), params.kp_per_s, params.kv_V_s_per_mm, integral_gain,
                     params.velocity_feedforward, coulomb_V, static_V,
                     params.stribeck_velocity_mm_s, smoothing_mm_s])


def friction_smoothing_mm_s(friction_V, velocity_per_V):
    """The velocity (mm/s) over which the friction's sign is smoothed linearly:
    ``FRICTION_SMOOTHING_MM_S``, or wider where one loop step could not resolve it.

    The friction is taken from the velocity at the step's start, so within the smoothing
    it acts as a damping of friction_V / width, which one step changes the velocity by
    ``velocity_per_V`` (mm/s per V held over the step) times: beyond 1 the step overshoots
    zero velocity and the loop chatters there, a numerical oscillation no axis has. The
    width is kept where that gain is 1 at most (heavy friction at a long loop step).
    """
    return max(FRICTION_SMOOTHING_MM_S, friction_V * abs(velocity_per_V))


def stribeck_V(velocity_mm_s, coulomb_V, static_V, stribeck_velocity_mm_s):
    """The Stribeck friction's magnitude (V): coulomb + (static − coulomb)·exp(−(v/v_s)²)
    (Armstrong-Hélouvry et al. 1994, Eq. 2, δ = 2), for a float v."""
    ratio = velocity_mm_s / stribeck_velocity_mm_s
    square = ratio * ratio
    decay = 0.0 if square > DECAY_UNDERFLOW else math.exp(-square)
    return coulomb_V + (static_V - coulomb_V) * decay


def friction_V(velocity_mm_s, coulomb_V, damping_V_s_per_mm, rise_coulomb_V, static_V,
               stribeck_velocity_mm_s, smoothing_mm_s):
    """The friction opposing ``velocity_mm_s`` (V, positive along +v): Coulomb and Stribeck
    (:func:`stribeck_V`) smoothed linearly over |v| < ``smoothing_mm_s``
    (:func:`friction_smoothing_mm_s`), plus viscous; for floats (the compiled loop passes
    no arrays between functions: that would need numba's runtime)."""
    total = damping_V_s_per_mm * velocity_mm_s
    if coulomb_V != 0.0 or rise_coulomb_V != 0.0 or static_V != 0.0:  # no division when none
        sign = min(max(velocity_mm_s / smoothing_mm_s, -1.0), 1.0)
        magnitude = coulomb_V
        if rise_coulomb_V != 0.0 or static_V != 0.0:
            magnitude += stribeck_V(velocity_mm_s, rise_coulomb_V, static_V,
                                    stribeck_velocity_mm_s)
        total += magnitude * sign
    return total


def run_loop(coefficients, steps, references_mm, disturbances_V, state, buffer, positions_mm,
             controls_V):
    """Advance the closed loop over consecutive samples (the one kernel of FMU and fit).

    Parameters
    ----------
    coefficients : sequence of float
        :func:`loop_coefficients`.
    steps : sequence of int
        Internal steps in each sample's communication interval.
    references_mm : sequence of float
        Reference at each sample's end; it is ramped linearly from the previous one over the
        interval (first-order hold).
    disturbances_V : sequence of float
        Known force over each interval as an equivalent command (F / force constant).
    state : mutable sequence of float, length ``STATE_SIZE``
        Updated in place.
    buffer : mutable sequence of float
        The delay line, ``ServoParams.buffer_size`` commands, updated in place.
    positions_mm : mutable sequence of float
        Receives the position at each sample's end.
    controls_V : mutable sequence of float
        Receives the controller output (V) of each sample's last step (unchanged for a
        sample without steps).

    The PID and NPID integrate and differentiate the error; the cascade integrates its
    bracket kp·e + vff·dr/dt − dx/dt (the ramped reference's slope over the interval).
    """
    a11, a12, a21, a22, late1, late2, early1, early2 = coefficients[0:8]
    kp, ki, kd, ko, e_max, nonlinear = coefficients[8:14]
    dt, delay = coefficients[16], coefficients[17]
    cascade, kp_per_s, kv, kv_tn, feedforward = coefficients[18:23]
    coulomb_V, damping_V_s_per_mm = coefficients[14], coefficients[15]
    rise_V, static_V, stribeck_mm_s, smoothing_mm_s = coefficients[23:27]
    x1, x2, integral, previous, start_mm = state[0], state[1], state[2], state[3], state[4]
    head = int(state[5])
    size = len(buffer)
    shift = int(delay)
    resisted = resists(coulomb_V, damping_V_s_per_mm, rise_V, static_V)
    for i in range(len(steps)):
        n_steps = steps[i]
        end_mm = references_mm[i]
        force_V = disturbances_V[i]
        slope_mm_s = (end_mm - start_mm) / (n_steps * dt) if n_steps > 0 else 0.0
        for k in range(1, n_steps + 1):
            error = start_mm + (end_mm - start_mm) * (k - 1) / n_steps - x1
            if cascade != 0.0:
                bracket = kp_per_s * error + feedforward * slope_mm_s - x2
                integral += 0.5 * (bracket + previous) * dt
                previous = bracket
                command = kv * bracket + kv_tn * integral
            else:
                if nonlinear != 0.0:
                    error = error * npid_gain(error, ko, e_max)
                integral += 0.5 * (error + previous) * dt
                derivative = (error - previous) / dt
                previous = error
                command = kp * error + ki * integral + kd * derivative
            buffer[head] = command
            controls_V[i] = command
            late = head - shift  # the delay line's index arithmetic without a modulo
            if late < 0:  # (an integer division per step, on the head's dependency chain)
                late += size
            early = late - 1 if late > 0 else size - 1
            command_late = buffer[late]
            command_early = buffer[early]
            head = head + 1 if head + 1 < size else 0
            force = force_V
            if resisted:
                force = force_V - friction_V(x2, coulomb_V, damping_V_s_per_mm, rise_V,
                                             static_V, stribeck_mm_s, smoothing_mm_s)
            u_late = command_late + force
            u_early = command_early + force
            x1, x2 = (a11 * x1 + a12 * x2 + late1 * u_late + early1 * u_early,
                      a21 * x1 + a22 * x2 + late2 * u_late + early2 * u_early)
        if n_steps > 0:
            start_mm = end_mm
        positions_mm[i] = x1
    state[0], state[1], state[2], state[3], state[4], state[5] = (
        x1, x2, integral, previous, start_mm, float(head))


def resists(coulomb_V, damping_V_s_per_mm, rise_coulomb_V, static_V):
    """Whether a friction force acts in :func:`run_loop` (Coulomb, viscous or Stribeck): where
    none does (:func:`friction_V` would return 0), the force is the known one as it is and
    the velocity leaves the step's chain of dependent operations (a third of its time).
    Floats, as :func:`friction_V`'s."""
    return (coulomb_V != 0.0 or damping_V_s_per_mm != 0.0 or rise_coulomb_V != 0.0
            or static_V != 0.0)


def is_linear(coefficients):
    """Whether :func:`run_loop` is linear in its state and inputs: PID or cascade, no
    Coulomb or Stribeck friction."""
    return (coefficients[13] == 0.0 and coefficients[14] == 0.0 and coefficients[23] == 0.0
            and coefficients[24] == 0.0)


def loop_propagator(coefficients, n_steps, buffer_size):
    """P with z' = P·(z, reference_mm, force_V) for ``n_steps`` of a linear loop.

    z = (position_mm, velocity_mm_s, integral_V, previous_error_mm, reference start_mm,
    the delay line read from its head). Column j is :func:`run_loop` applied to the j-th
    unit vector, so the propagator is the kernel itself, composed over the interval.
    """
    size = 5 + buffer_size
    columns = []
    for j in range(size + 2):
        unit = [0.0] * (size + 2)
        unit[j] = 1.0
        state, buffer = unit[:5] + [0.0], unit[5:size]
        run_loop(coefficients, [n_steps], [unit[size]], [unit[size + 1]], state, buffer, [0.0],
                 [0.0])
        head = int(state[5])
        columns.append(state[:5] + buffer[head:] + buffer[:head])
    return np.array(columns).T


def numba_ready_loop(numba):
    """:func:`run_loop` with its calls of :func:`npid_gain` and :func:`friction_V` compiled
    (:func:`with_compiled_callees`): what numba's JIT (:func:`compiled_loop`) and its
    ahead-of-time compiler (feedaxis.kernel_build) take."""
    return with_compiled_callees(numba, run_loop, npid_gain, resists,
                                 with_compiled_callees(numba, friction_V, stribeck_V))


def with_compiled_callees(numba, function, *callees, **options):
    """``function``'s code with its calls of ``callees`` bound to numba-compiled copies of
    them, compiled with numba's ``options`` (numba compiles calls to compiled functions
    only; cached on disk also where site-packages is read-only:
    :func:`.numba_cache.cached_njit`)."""
    from .numba_cache import cached_njit

    namespace = {**function.__globals__, **{
        callee.__name__: cached_njit(numba, callee, **options) for callee in callees}}
    return types.FunctionType(function.__code__, namespace, function.__name__)


@lru_cache(maxsize=1)
def compiled_loop():
    """:func:`run_loop` compiled by numba (cached on disk, also where site-packages is
    read-only: :func:`.numba_cache.cached_njit`): the same code object, its call of
    :func:`npid_gain` bound to a compiled :func:`npid_gain`; about 40x faster.

    numba is imported here, not with the module: the FMU and the CLI's quick commands do
    without it.
    """
    import numba

    from .numba_cache import cached_njit

    return cached_njit(numba, numba_ready_loop(numba), nogil=True)


def shipped_loop():
    """(:func:`run_loop` compiled ahead of time, or None; why it did not load, or None).

    The FMUs carry the compiled module beside this file (:mod:`.kernel`,
    feedaxis.kernel_build); feedaxis's own copy of the physics has none (None, None).
    """
    module, failure = shipped_kernel()
    return (module.run_loop if module is not None else None), failure


def force_command_V(disturbance_N, force_N, force_constant_N_per_V):
    """The known axial force (disturbance and constant force, N) as a command (V)."""
    return (disturbance_N + force_N) / force_constant_N_per_V


def newest_command_V(commands_V, head):
    """The controller output of the last loop step: the delay line's entry before ``head``
    (run_loop's state[5])."""
    return commands_V[(int(head) - 1) % len(commands_V)]


def whole_steps(pending_s, duration_s, time_step_s):
    """Internal steps that fit in ``pending_s + duration_s``, and the remainder carried (s)."""
    elapsed_steps = (pending_s + duration_s) / time_step_s
    n_steps = int(elapsed_steps + 1e-9)  # floor: elapsed_steps >= 0
    remainder_s = (elapsed_steps - n_steps) * time_step_s
    return n_steps, remainder_s if remainder_s > 0.0 else 0.0


def loop_budget_problem(time_s, time_step_s):
    """Where stepping the loop every ``time_step_s`` through samples at ``time_s`` costs more
    than a record may: (index of the sample, why), or None.

    A gap of more than :data:`MAX_INTERVAL_STEPS` loop steps before a sample, or a record
    needing more than :data:`MAX_LOOP_STEPS` in all, is refused rather than simulated for
    minutes or hours.
    """
    interval_s = np.diff(np.asarray(time_s, dtype=float))
    steps = interval_s / time_step_s
    gaps = np.flatnonzero(steps > MAX_INTERVAL_STEPS)
    if gaps.size:
        i = gaps[0]
        return i + 1, (f"a gap of {interval_s[i]:g} s before this sample, {steps[i]:.3g} steps "
                       f"of the {time_step_s:g} s control loop; samples may be at most "
                       f"{MAX_INTERVAL_STEPS:g} steps ({MAX_INTERVAL_STEPS * time_step_s:g} s) "
                       "apart: split the record at the gap into two cases")
    over = np.flatnonzero(np.cumsum(steps) > MAX_LOOP_STEPS)
    if over.size:
        return over[0] + 1, (f"the record reaches {MAX_LOOP_STEPS:g} steps of the "
                             f"{time_step_s:g} s control loop here ({steps.sum():.3g} in all), "
                             f"the most one may need: split it into cases of at most "
                             f"{MAX_LOOP_STEPS * time_step_s:g} s")
    return None


def step_counts(time_s, time_step_s):
    """Internal steps between consecutive samples, carrying remainders as :class:`Servo` does;
    the first sample gets 0 (the loop starts there). Samples beyond the loop's budget
    (:func:`loop_budget_problem`) raise :class:`ParameterError` naming ``time_s``."""
    problem = loop_budget_problem(time_s, time_step_s)
    if problem is not None:
        raise ParameterError(f"sample {problem[0] + 1}: {problem[1]}", "time_s")
    counts = np.zeros(len(time_s), dtype=np.int64)
    compiled_carry()(np.diff(np.asarray(time_s, dtype=float)), float(time_step_s), counts)
    return counts


def carry_steps(intervals_s, time_step_s, counts):
    """``counts[i + 1]``: the internal steps in ``intervals_s[i]``, each interval's remainder
    carried into the next (:func:`whole_steps`, as :class:`Servo` steps)."""
    pending_s = 0.0
    for i in range(len(intervals_s)):
        counts[i + 1], pending_s = whole_steps(pending_s, intervals_s[i], time_step_s)


@lru_cache(maxsize=1)
def compiled_carry():
    """:func:`carry_steps` compiled by numba (a 500 s record at 1 ms: about 5 ms, against
    0.36 s in Python)."""
    import numba

    from .numba_cache import cached_njit

    return cached_njit(numba, with_compiled_callees(numba, carry_steps, whole_steps))


def forces_V(params, disturbance_N, size):
    """The force on the axis over each interval as an equivalent command (V): the known
    ``disturbance_N`` (None: none) plus the constant force ``force_N``, over the force
    constant."""
    force_N = np.full(size, params.force_N) if disturbance_N is None else \
        np.asarray(disturbance_N, dtype=float) + params.force_N
    return np.ascontiguousarray(force_N / params.force_constant_N_per_V)


@one_blas_thread
def simulate_record(params, time_s, reference_mm, disturbance_N=None, counts=None):
    """(position_mm, control_V) at each sample of a tracking record, the loop starting at
    rest on the first reference; the same loop as :class:`Servo` stepped with the sample
    intervals. ``control_V`` is the controller output of each sample's last loop step (0 at
    the first sample), what a drive records.

    ``counts`` (:func:`step_counts`) may be passed to save recomputing it.
    """
    reference_mm = np.ascontiguousarray(reference_mm, dtype=float)
    counts = step_counts(time_s, params.time_step_s) if counts is None else counts
    state = np.array([reference_mm[0], 0.0, 0.0, 0.0, reference_mm[0], 0.0])
    positions_mm = np.empty_like(reference_mm)
    controls_V = np.zeros_like(reference_mm)
    compiled_loop()(loop_coefficients(params), counts, reference_mm,
                    forces_V(params, disturbance_N, reference_mm.size), state,
                    np.zeros(params.buffer_size), positions_mm, controls_V)
    return positions_mm, controls_V


def simulate(params, time_s, reference_mm, disturbance_N=None, counts=None):
    """Position (mm) at each sample of a tracking record (:func:`simulate_record`)."""
    return simulate_record(params, time_s, reference_mm, disturbance_N, counts)[0]


class LoopRunsAway(ParameterError):
    """The closed loop runs away with these plant, friction and controller values: its
    position leaves any axis (beyond ±``MAX_POSITION_MM``) or is not finite."""

    def __init__(self, params):
        super().__init__(
            f"the closed position loop runs away (beyond ±{MAX_POSITION_MM:g} mm) with plant "
            f"gain {params.plant_gain_mm_per_Vs2:g} mm/(V.s2), damping "
            f"{params.plant_damping_per_s:g} 1/s, stiffness {params.plant_stiffness_per_s2:g} "
            f"1/s2, delay {params.delay_s:g} s, friction {params.friction_N:g} N + "
            f"{params.damping_N_s_per_mm:g} N.s/mm under {controller_text(params)}: the "
            "plant and the controller do not make a stable loop", "tracking model")


def controller_text(params):
    """The controller's gains in words, for messages."""
    if params.controller == "cascade":
        integral = f", tn {params.tn_s:g} s" if params.tn_s > 0 else ""
        return (f"a cascade with kp {params.kp_per_s:g} 1/s, kv {params.kv_V_s_per_mm:g} "
                f"V.s/mm{integral}, feed-forward {params.velocity_feedforward:g}")
    return f"kp {params.kp_V_per_mm:g} V/mm"


def check_runs(params, positions_mm):
    """Raise :class:`LoopRunsAway` when positions :func:`simulate` gave with ``params`` leave
    any axis. (A fit's trial values may run away: the optimiser steps back from them.)"""
    if not np.all(np.abs(positions_mm) <= MAX_POSITION_MM):
        raise LoopRunsAway(params)


class Servo:
    """Closed position loop advanced in communication steps of any length.

    The reference is ramped linearly from its previous value to the new one over each
    communication step (first-order hold), so a sampled reference is followed smoothly;
    this delays the reference by one communication step and leaves the loop's tracking
    error unchanged.

    ``loop`` is the implementation of :func:`run_loop` to step: by default the compiled one
    an FMU carries (:func:`shipped_loop`), which then runs every controller mode; without
    it, :func:`run_loop` itself, and a linear loop (PID, no Coulomb friction) advances by
    one propagator matrix per communication step instead (:func:`loop_propagator`).
    """

    def __init__(self, params: ServoParams, initial_reference_mm=0.0, loop=None):
        self.params = params
        self._compiled = loop if loop is not None else shipped_loop()[0]
        coefficients = loop_coefficients(params)
        if self._compiled is None:
            self._coefficients = coefficients.tolist()
            linear = (is_linear(self._coefficients)
                      and params.delay_steps <= MAX_PROPAGATOR_DELAY_STEPS)
        else:
            self._coefficients = coefficients
            # one call's samples: steps, reference, force (written through views), position
            self._samples = (np.zeros(1, dtype=np.int64), np.zeros(1), np.zeros(1))
            self._inputs = tuple(memoryview(array) for array in self._samples)
            self._positions = np.zeros(1)
            self._controls = np.zeros(1)
            linear = False
        self._propagators = {} if linear else None
        self._size = 5 + params.buffer_size
        self._vector = self._spare = self._spare_view = None
        self.restore({"loop": [float(initial_reference_mm), 0.0, 0.0, 0.0,
                               float(initial_reference_mm), 0.0],
                      "commands_V": [0.0] * params.buffer_size, "pending_s": 0.0})

    # The loop state is held in one of two forms: run_loop's (self._state with the head,
    # self._buffer; lists for the Python loop, float64 arrays for the compiled one), or one
    # float64 vector in the propagator's order for the linear path (z, reference_mm,
    # force_V; delay line read from its head). Both keep position, velocity, integral,
    # previous error and reference at indices 0-4; self._loop is the form in use (the list,
    # or a memoryview of the array or vector: all index to Python floats; self._commands the
    # delay line of run_loop's form, likewise).

    @property
    def position_mm(self):
        return self._loop[0]

    @property
    def velocity_mm_s(self):
        return self._loop[1]

    @property
    def reference_mm(self):
        return self._loop[4]

    @property
    def tracking_error_mm(self):
        """Position minus reference at the end of the last step (mm): the sign of every
        deviation in feedaxis (measured − commanded, ISO 230-2), of tracking.csv's
        actual_mm − reference_mm and of the report."""
        return self.outputs()[2]

    def outputs(self):
        """(position_mm, velocity_mm_s, tracking_error_mm, control_V) at the end of the last
        step; control_V is the last command, the newest in the delay line."""
        loop = self._loop
        return loop[0], loop[1], loop[0] - loop[4], self.control_V

    @property
    def control_V(self):
        """The controller output of the last loop step (V)."""
        if self._vector is not None:  # the delay line read from its head: newest last
            return float(self._vector[4 + self.params.buffer_size])
        return newest_command_V(self._commands, self._loop[5])  # Python floats, as self._loop

    @property
    def coefficients(self):
        """:func:`loop_coefficients` as the loop in use reads them."""
        return self._coefficients

    def state(self):
        """All internal state as plain Python values (for FMU get/set state)."""
        self._to_loop_form()
        return {"loop": [float(v) for v in self._state],
                "commands_V": [float(v) for v in self._buffer], "pending_s": self.pending_s}

    def restore(self, state):
        """Restore what :meth:`state` returned (ValueError if it is not one of this loop's:
        the compiled loop indexes the delay line by the stored head unchecked)."""
        loop = [float(v) for v in state["loop"]]
        commands_V = [float(v) for v in state["commands_V"]]
        pending_s = float(state["pending_s"])
        if (len(loop) != STATE_SIZE or len(commands_V) != self.params.buffer_size
                or not (0 <= loop[5] < self.params.buffer_size and loop[5] == int(loop[5]))
                or not math.isfinite(sum(loop) + sum(commands_V))
                or not 0.0 <= pending_s < self.params.time_step_s):
            raise ValueError(f"not a state of this loop: {STATE_SIZE} finite loop values with "
                             f"a delay-line head, {self.params.buffer_size} finite commands and "
                             f"0 <= pending_s < time_step_s are needed")
        self._set_loop_form(loop, commands_V)
        self.pending_s = pending_s

    def advance(self, duration_s, reference_mm, disturbance_N=0.0):
        """Run the loop for ``duration_s`` toward ``reference_mm`` under ``disturbance_N``.

        Time advances in whole internal steps of ``params.time_step_s``; a remainder is
        carried to the next call, so any communication step keeps exact time.
        """
        # one test of valid inputs (every FMU step); the checks name what is wrong
        if not (0.0 <= duration_s < math.inf and math.isfinite(reference_mm + disturbance_N)):
            require_non_negative("duration_s", duration_s)
            require_finite("reference_mm", reference_mm)
            require_finite("disturbance_N", disturbance_N)
        n_steps, self.pending_s = whole_steps(self.pending_s, duration_s, self.params.time_step_s)
        if n_steps == 0:  # run_loop leaves the state as it is
            return self._loop[0]
        force_V = force_command_V(disturbance_N, self.params.force_N,
                                  self.params.force_constant_N_per_V)
        if self._compiled is not None:
            steps, references, forces = self._inputs
            steps[0], references[0], forces[0] = n_steps, reference_mm, force_V
            self._compiled(*self._kernel_arguments)
        elif self._propagators is None:
            self._to_loop_form()
            run_loop(self._coefficients, [n_steps], [float(reference_mm)], [force_V],
                     self._state, self._buffer, [0.0], [0.0])
        else:
            self._propagate(n_steps, float(reference_mm), force_V)
        return self._loop[0]  # position_mm without the property's call: every FMU step

    def _set_loop_form(self, state, buffer):
        """Hold ``state`` and ``buffer`` (lists) in run_loop's form."""
        if self._compiled is None:
            self._state, self._buffer = state, buffer
            self._loop, self._commands = self._state, self._buffer
        else:
            self._state, self._buffer = np.array(state), np.array(buffer)
            self._loop, self._commands = memoryview(self._state), memoryview(self._buffer)
            self._kernel_arguments = (self._coefficients, *self._samples, self._state,
                                      self._buffer, self._positions, self._controls)
        self._vector = None

    def _to_loop_form(self):
        """Put the state in run_loop's form (delay line re-headed) if it is a vector."""
        if self._vector is not None:
            values = self._vector[:self._size].tolist()
            self._set_loop_form(values[:5] + [0.0], values[5:])

    def _to_vector(self):
        """Put the state in vector form (propagator order) if it is in lists."""
        if self._vector is None:
            head = int(self._state[5])
            self._vector = np.array(self._state[:5] + self._buffer[head:] + self._buffer[:head]
                                    + [0.0, 0.0])
            self._spare = np.empty_like(self._vector)
            self._loop, self._spare_view = memoryview(self._vector), memoryview(self._spare)

    def _propagate(self, n_steps, reference_mm, force_V):
        """The linear loop over ``n_steps`` in one matrix product, into a preallocated vector."""
        propagator = self._propagators.get(n_steps)
        if propagator is None:
            # two zero rows: the product fills the whole spare vector, whose last two slots
            # (reference, force) are written before the next product
            propagator = np.vstack((loop_propagator(self._coefficients, n_steps,
                                                    self.params.buffer_size),
                                    np.zeros((2, self._size + 2))))
            self._propagators[n_steps] = propagator
        self._to_vector()
        loop = self._loop
        loop[-2] = reference_mm
        loop[-1] = force_V
        np.dot(propagator, self._vector, out=self._spare)
        self._vector, self._spare = self._spare, self._vector
        self._loop, self._spare_view = self._spare_view, loop
