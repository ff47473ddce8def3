"""Example cases: the seed 001 micro ball screw, reconstructed from its published numbers.

Seed 001 publishes the fitted lead error f1 and eccentricity f2 of a C3 micro ball screw
(lead 1 mm, stroke 5 mm, 5-phase stepper with 0.72° steps) and a validation run of 2,501
laser points every 0.002 mm. The motor coefficients are not published: the reconstruction
adds a motor ripple of 0.3 µm peak to valley (0.12 / 0.09 µm, so that with the noise the
short-wave ripple is about the paper's 0.5 µm) and 0.05 µm Gaussian measurement noise.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .case import write_case
from .physics import geometry, motor

SEED001_AXIS = {
    "name": "micro ball screw of seed 001 (reconstructed: published f1, f2 + motor ripple + noise)",
    "screw": {"lead_mm": 1.0},
    "motor": {"step_angle_deg": 0.72, "error_period_steps": 10},
}
SEED001_LEAD = {"offset_um": 0.2515, "slope_um_per_mm": -0.5084}
SEED001_ECCENTRICITY = {"cos_um": 0.2005, "sin_um": 0.1504}
SEED001_MOTOR = {"cos_um": 0.12, "sin_um": 0.09}
SEED001_NOISE_UM = 0.05
SEED001_SEED = 2023
BUNDLED_CASE = Path(__file__).resolve().parent / "data" / "micro_bms_seed001"


def seed001_error_um(position_mm):
    """Noise-free error of the reconstructed axis: f1 + f2 (seed 001) + motor ripple (µm)."""
    lead_mm = SEED001_AXIS["screw"]["lead_mm"]
    return (geometry.lead_error_um(position_mm, **SEED001_LEAD)
            + geometry.eccentricity_error_um(position_mm, lead_mm, **SEED001_ECCENTRICITY)
            + motor.motor_step_error_um(position_mm, lead_mm, 0.72, 10,
                                        (SEED001_MOTOR["cos_um"],), (SEED001_MOTOR["sin_um"],)))


def write_seed001_case(folder, noise_um=SEED001_NOISE_UM, seed=SEED001_SEED):
    """Write the 2,501-point validation run (0 to 5 mm every 0.002 mm, one + run)."""
    position_mm = np.round(np.linspace(0.0, 5.0, 2501), 6)
    error_um = seed001_error_um(position_mm) + np.random.default_rng(seed).normal(
        0.0, noise_um, position_mm.size)
    return write_case(folder, SEED001_AXIS, positioning={
        "target_mm": position_mm, "error_um": np.round(error_um, 5),
        "direction": np.ones_like(position_mm), "run": np.ones_like(position_mm)})
