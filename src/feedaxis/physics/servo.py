"""Position servo of a ball-screw drive with a PID or NPID controller, seed 002 Eq. 1-8.

Plant (Eq. 1, Googol XY table, x axis): G(s) = 78020 / (s² + 163 s + 193.3), command in V,
position in mm, with a 1.2 ms transport delay on the command. Controller (Eq. 2, 6):
C(s) = K_P + K_I/s + K_D·s acting on the tracking error e = reference - position (mm).
NPID (Eq. 7-8) puts the nonlinear gain K(e) = (exp(KO·e) + exp(-KO·e)) / 2 = cosh(KO·e)
in front of the PID, held at K(e_max) for |e| > e_max.

The loop runs at a fixed internal step: the plant is discretised exactly for a command held
over each step (zero-order hold), the integral by the trapezoidal rule and the derivative
by a backward difference. An axial disturbance force enters at the plant input as an
equivalent command F / force_constant (the paper gives no force scaling; see
:class:`ServoParams`).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, fields

import numpy as np
from scipy.linalg import expm

from .checks import require_finite, require_non_negative, require_positive


@dataclass(frozen=True)
class ServoParams:
    """Plant, controller and loop timing. Defaults: seed 002 Eq. 1, 6, 8.

    ``force_constant_N_per_V`` converts the disturbance force to the equivalent plant
    command; seed 002 does not publish it, the default 100 N/V is an assumption.
    """

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

    def __post_init__(self):
        for field in fields(self):
            value = getattr(self, field.name)
            if field.name in ("delay_s", "ki_V_per_mm_s", "kd_V_s_per_mm", "ko_per_mm",
                              "plant_stiffness_per_s2"):
                require_non_negative(field.name, value)
            elif field.name != "nonlinear":
                require_positive(field.name, value)

    @property
    def delay_steps(self):
        """Transport delay in whole internal steps."""
        return int(round(self.delay_s / self.time_step_s))


def npid_gain(error_mm, ko_per_mm, e_max_mm):
    """K(e) = cosh(KO·e), held at K(e_max) beyond ±e_max (seed 002 Eq. 8), for a float e."""
    return math.cosh(ko_per_mm * min(abs(error_mm), e_max_mm))


def discrete_plant(params):
    """Exact zero-order-hold discretisation (Ad, Bd) of Eq. 1 at ``params.time_step_s``.

    State x = (position_mm, velocity_mm_s); ẋ = [[0, 1], [-a0, -a1]] x + [0, b] u.
    """
    continuous = np.array([[0.0, 1.0, 0.0],
                           [-params.plant_stiffness_per_s2, -params.plant_damping_per_s,
                            params.plant_gain_mm_per_Vs2],
                           [0.0, 0.0, 0.0]])
    augmented = expm(continuous * params.time_step_s)
    return augmented[:2, :2], augmented[:2, 2]


class Servo:
    """Closed position loop advanced in communication steps of any length.

    The reference is ramped linearly from its previous value to the new one over each
    communication step (first-order hold), so a sampled reference is followed smoothly;
    this delays the reference by one communication step and leaves the loop's tracking
    error unchanged.
    """

    def __init__(self, params: ServoParams, initial_reference_mm=0.0):
        self.params = params
        transition, command_gain = discrete_plant(params)
        (self._a11, self._a12), (self._a21, self._a22) = transition.tolist()
        self._b1, self._b2 = command_gain.tolist()
        self.position_mm = float(initial_reference_mm)
        self.velocity_mm_s = 0.0
        self.reference_mm = float(initial_reference_mm)
        self.integral_V = 0.0
        self.previous_error_mm = 0.0
        self.pending_s = 0.0
        self.commands_V = deque([0.0] * params.delay_steps, maxlen=params.delay_steps or None)

    @property
    def tracking_error_mm(self):
        """Reference minus position at the end of the last step (mm)."""
        return self.reference_mm - self.position_mm

    def state(self):
        """All internal state as plain Python values (for FMU get/set state)."""
        return {"position_mm": self.position_mm, "velocity_mm_s": self.velocity_mm_s,
                "reference_mm": self.reference_mm, "integral_V": self.integral_V,
                "previous_error_mm": self.previous_error_mm, "pending_s": self.pending_s,
                "commands_V": list(self.commands_V)}

    def restore(self, state):
        """Restore what :meth:`state` returned."""
        for name in ("position_mm", "velocity_mm_s", "reference_mm", "integral_V",
                     "previous_error_mm", "pending_s"):
            setattr(self, name, float(state[name]))
        self.commands_V = deque(state["commands_V"], maxlen=self.commands_V.maxlen)

    def advance(self, duration_s, reference_mm, disturbance_N=0.0):
        """Run the loop for ``duration_s`` toward ``reference_mm`` under ``disturbance_N``.

        Time advances in whole internal steps of ``params.time_step_s``; a remainder is
        carried to the next call, so any communication step keeps exact time.
        """
        require_non_negative("duration_s", duration_s)
        require_finite("reference_mm", reference_mm)
        require_finite("disturbance_N", disturbance_N)
        p = self.params
        dt = p.time_step_s
        elapsed_steps = (self.pending_s + duration_s) / dt
        n_steps = int(math.floor(elapsed_steps + 1e-9))
        self.pending_s = max(0.0, (elapsed_steps - n_steps) * dt)
        if n_steps == 0:
            return self.position_mm
        start_mm = self.reference_mm
        disturbance_V = disturbance_N / p.force_constant_N_per_V
        x1, x2 = self.position_mm, self.velocity_mm_s
        integral, previous = self.integral_V, self.previous_error_mm
        commands = self.commands_V
        for k in range(1, n_steps + 1):
            reference = start_mm + (reference_mm - start_mm) * (k - 1) / n_steps
            command = commands[0] if commands else None
            error = reference - x1
            gained = error * npid_gain(error, p.ko_per_mm, p.e_max_mm) if p.nonlinear else error
            integral += 0.5 * (gained + previous) * dt
            derivative = (gained - previous) / dt
            previous = gained
            output = p.kp_V_per_mm * gained + p.ki_V_per_mm_s * integral + p.kd_V_s_per_mm * derivative
            if command is None:
                command = output
            else:
                commands.append(output)
            u = command + disturbance_V
            x1, x2 = (self._a11 * x1 + self._a12 * x2 + self._b1 * u,
                      self._a21 * x1 + self._a22 * x2 + self._b2 * u)
        self.position_mm, self.velocity_mm_s = x1, x2
        self.integral_V, self.previous_error_mm = integral, previous
        self.reference_mm = float(reference_mm)
        return self.position_mm
