"""Stepper-motor angular error mapped to axial displacement, Liu 2022 Eq. 6, 9, 10.

The rotor's angular deviation Δφ is periodic over ``error_period_steps`` full steps
(a 5-phase hybrid motor: 10 steps, a 2-phase one: 4). Through the screw it becomes the
axial displacement error Δφ/2π × lead (Eq. 9-10); Liu 2023 fits it with one Fourier term
f3 = a3·cos(ωy) + b3·sin(ωy) + c3, ω = 2π / period.
"""
from __future__ import annotations

import math

from .checks import require_positive, require_representable
from .scalar import values, values_and_module


def motor_error_period_mm(lead_mm, step_angle_deg, error_period_steps):
    """Axial wavelength of the motor error: steps × step angle / 360° × lead (mm).

    Liu 2023 case: 10 × 0.72° / 360° × 1 mm = 0.02 mm.
    """
    require_positive("lead_mm", lead_mm)
    require_positive("step_angle_deg", step_angle_deg)
    require_positive("error_period_steps", error_period_steps)
    period_mm = angular_to_axial_um(error_period_steps * step_angle_deg, lead_mm) * 1e-3
    require_representable("the motor error period (mm)", period_mm, lead_mm=lead_mm,
                          step_angle_deg=step_angle_deg, error_period_steps=error_period_steps)
    return period_mm


def angular_to_axial_um(angle_deg, lead_mm):
    """Axial displacement Δφ/2π × p (Liu 2022 Eq. 9) of a rotor angle Δφ (deg), in µm."""
    return values(angle_deg) / 360.0 * lead_mm * 1e3


def motor_step_error_um(position_mm, lead_mm, step_angle_deg, error_period_steps,
                        cos_um, sin_um):
    """Axial motor error as a Fourier series over the motor error period (Liu 2022 Eq. 6, 10).

    Parameters
    ----------
    position_mm : array_like
        Axis position (mm); the rotor angle is position / lead × 360°.
    lead_mm, step_angle_deg, error_period_steps : float
        Screw lead (mm), full-step angle (deg) and steps per error period.
    cos_um, sin_um : sequence of float
        Harmonic k = 1, 2, ... cosine and sine amplitudes of the axial error (µm), as many
        of each.
    """
    period_mm = motor_error_period_mm(lead_mm, step_angle_deg, error_period_steps)
    return motor_error_um(position_mm, period_mm, cos_um, sin_um)


def motor_error_um(position_mm, period_mm, cos_um, sin_um):
    """The Fourier series of :func:`motor_step_error_um` over a known period (mm), unchecked:
    f = Σ_k a_k cos(k ω y) + b_k sin(k ω y), ω = 2π / period (Liu 2022 Eq. 10)."""
    position_mm, xp = values_and_module(position_mm)
    phase_rad = 2.0 * math.pi * position_mm / period_mm
    error_um = 0.0 * phase_rad
    for k in range(len(cos_um)):  # indexed, not enumerate(zip()): a fifth less per FMU step
        a_um, b_um = cos_um[k], sin_um[k]
        if a_um or b_um:  # a harmonic left at zero adds nothing: skip its cos and sin
            order_phase_rad = (k + 1) * phase_rad
            error_um = error_um + a_um * xp.cos(order_phase_rad) + b_um * xp.sin(order_phase_rad)
    return error_um
