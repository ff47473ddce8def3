"""Example cases generated from published numbers with the project's physics.

The Liu 2023 micro ball screw (the demo case):

Liu 2023 publishes the fitted lead error f1 and eccentricity f2 of a C3 micro ball screw
(lead 1 mm, stroke 5 mm, 5-phase stepper with 0.72° steps) and a validation run of 2,501
laser points every 0.002 mm. The motor coefficients are not published: the reconstruction
adds a motor ripple of 0.3 µm peak to valley (0.12 / 0.09 µm, so that with the noise the
short-wave ripple is about the paper's 0.5 µm) and 0.05 µm Gaussian measurement noise.

Rong et al. 2023 thermal tests: the X axis of Table 1 + Table 3 under a Table 2 loading (stroke
0-500 mm assumed), with a lead error and 1 µm noise, sampled by + runs over 11 targets.

The laser example (``data/laser_example``, shipped for ``feedaxis import``): a Renishaw
``.rtl`` of an ISO 230-2 test of a 500 mm axis with a 10 mm lead, generated from a known
lead error and backlash, and the ``axis.toml`` it is imported with.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .case import write_case
from .physics import geometry, motor, thermal

SEED001_AXIS = {
    "name": "micro ball screw of Liu 2023 (reconstructed: published f1, f2 + motor ripple + noise)",
    "screw": {"lead_mm": 1.0},
    "motor": {"step_angle_deg": 0.72, "error_period_steps": 10},
}
SEED001_LEAD = {"offset_um": 0.2515, "slope_um_per_mm": -0.5084}
SEED001_ECCENTRICITY = {"cos_um": 0.2005, "sin_um": 0.1504}
SEED001_MOTOR = {"cos_um": 0.12, "sin_um": 0.09}
SEED001_NOISE_UM = 0.05
SEED001_SEED = 2023
BUNDLED_CASE = Path(__file__).resolve().parent / "data" / "micro_bms_seed001"
LASER_EXAMPLE = Path(__file__).resolve().parent / "data" / "laser_example"
LASER_LEAD_MM = 10.0
LASER_LEAD = {"offset_um": 1.5, "slope_um_per_mm": -0.02}
LASER_BACKLASH_UM = 3.0
LASER_NOISE_UM = 0.4
LASER_SEED = 230


def seed001_error_um(position_mm):
    """Noise-free error of the reconstructed axis: f1 + f2 (Liu 2023) + motor ripple (µm)."""
    lead_mm = SEED001_AXIS["screw"]["lead_mm"]
    return (geometry.lead_error_um(position_mm, **SEED001_LEAD)
            + geometry.eccentricity_error_um(position_mm, lead_mm, **SEED001_ECCENTRICITY)
            + motor.motor_step_error_um(position_mm, lead_mm, 0.72, 10,
                                        (SEED001_MOTOR["cos_um"],), (SEED001_MOTOR["sin_um"],)))


def write_seed001_case(folder, noise_um=SEED001_NOISE_UM, seed=SEED001_SEED, ripple=None):
    """Write the 2,501-point validation run (0 to 5 mm every 0.002 mm, one + run).

    ``ripple`` = (wavelength_mm, amplitude_um) adds a sinusoid no catalog effect explains,
    to try the loop on an uncatalogued error.
    """
    position_mm = np.round(np.linspace(0.0, 5.0, 2501), 6)
    error_um = seed001_error_um(position_mm) + np.random.default_rng(seed).normal(
        0.0, noise_um, position_mm.size)
    if ripple:
        wavelength_mm, amplitude_um = ripple
        error_um += amplitude_um * np.sin(2.0 * np.pi * position_mm / wavelength_mm + 0.4)
    return write_case(folder, SEED001_AXIS, positioning={
        "target_mm": position_mm, "error_um": np.round(error_um, 5),
        "direction": np.ones_like(position_mm), "run": np.ones_like(position_mm)})


TABLE2_AXIS = {"name": "Rong et al. 2023 X axis, Table 2 loading (synthetic)", "screw": {
    "lead_mm": 10.0, "length_m": 0.8, "diameter_m": 0.034, "density_kg_m3": 7800.0,
    "specific_heat_J_kgK": 448.0, "expansion_per_K": 11.7e-6, "nut_length_m": 0.212,
    "bearing_length_m": 0.03, "fixed_end_mm": -141.0}}
TABLE2_LEAD = {"offset_um": 2.0, "slope_um_per_mm": -0.01}


def write_table2_case(folder, feed_mm_min, params=None, noise_um=1.0, seed=0, run_every_s=360.0,
                      stroke_mm=(0.0, 500.0), axis_fixed_end_mm=None,
                      simulate=thermal.simulate_duty):
    """A thermal case: Table 2 duty at ``feed_mm_min`` over ``stroke_mm``; every
    ``run_every_s`` a + run over the stroke every 50 mm, 3 s per target;
    error = TE (Rong et al. 2023 Eq. 1-19) + lead error + noise.

    ``params`` (ThermalScrewParams, default Table 1 + Table 3 X) must match TABLE2_AXIS's
    geometry; axis.toml states ``axis_fixed_end_mm`` (default: the true P_f) as the user's
    prior knowledge. ``simulate`` is :func:`thermal.simulate_duty` (nut heat averaged over
    its path) or :func:`thermal.explicit_duty` (Eq. 10 stepped with the nut moving).
    """
    params = params or thermal.ThermalScrewParams()
    segments = thermal.table2_cycle(feed_mm_min, *stroke_mm)
    targets_mm = np.arange(stroke_mm[0], stroke_mm[1] + 1.0, 50.0)
    starts_s = np.arange(0.0, segments[-1].end_s - 60.0, run_every_s)
    time_s = (starts_s[:, None] + 3.0 * np.arange(targets_mm.size)[None, :]).ravel()
    target_mm = np.tile(targets_mm, starts_s.size)
    rise_K = simulate(params, segments, time_s)
    error_um = (thermal.thermal_error_um(params, rise_K, target_mm)
                + geometry.lead_error_um(target_mm, **TABLE2_LEAD)
                + np.random.default_rng(seed).normal(0.0, noise_um, target_mm.size))
    duty = {"start_s": [s.start_s for s in segments],
            "duration_s": [s.duration_s for s in segments],
            "feed_mm_min": [s.feed_mm_min for s in segments],
            "from_mm": [s.from_mm for s in segments], "to_mm": [s.to_mm for s in segments]}
    fixed_end_mm = params.fixed_end_mm if axis_fixed_end_mm is None else axis_fixed_end_mm
    axis = {**TABLE2_AXIS, "screw": {**TABLE2_AXIS["screw"], "fixed_end_mm": fixed_end_mm}}
    return write_case(folder, axis, duty=duty, positioning={
        "target_mm": target_mm, "error_um": error_um, "direction": np.ones_like(target_mm),
        "time_s": time_s})


def laser_example_rtl(seed=LASER_SEED):
    """The text of the shipped ``X-axis.rtl``: 11 targets P_i = (i - 1)·50 mm + r_i (ISO 230-2,
    r_i as ``feedaxis simulate iso230``), 5 cycles of a + and a - run, deviation = lead error
    ``LASER_LEAD`` + backlash ``LASER_BACKLASH_UM`` + Gaussian noise ``LASER_NOISE_UM``,
    rounded to 0.1 nm as a laser system writes it; air temperature 20.4 °C."""
    from .cosim.scenarios import iso230_targets
    from .importers.rtl import rtl_text

    rng = np.random.default_rng(seed)
    target_mm = np.round(iso230_targets(11, 50.0), 4)
    runs = []
    for _ in range(5):
        for direction in (1.0, -1.0):
            error_um = (geometry.lead_error_um(target_mm, **LASER_LEAD)
                        + geometry.backlash_error_um(direction, LASER_BACKLASH_UM)
                        + rng.normal(0.0, LASER_NOISE_UM, target_mm.size))
            runs.append((direction, np.round(error_um, 4)))
    user_text = {"Machine": "VMC-500", "Serial No": "example", "Date": "2026-01-15",
                 "By": "feedaxis", "Axis": "X", "Location": "generated",
                 "TITLE": f"feedaxis example: lead error {LASER_LEAD['offset_um']} um "
                          f"{LASER_LEAD['slope_um_per_mm']:+} um/mm, backlash "
                          f"{LASER_BACKLASH_UM} um, noise {LASER_NOISE_UM} um (seed {seed})"}
    environment = {"Air temp": "20.4", "Air Press": "1013.2", "Air Humid": "45",
                   "Mat temp 1": "20.6", "Exp coeff": "11.7"}
    return rtl_text(target_mm, runs, user_text, environment)
