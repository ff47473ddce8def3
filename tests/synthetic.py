"""Measurement cases generated from known parameters with a seeded generator.

Every error is computed by feedaxis.physics directly (not through the effect catalog), plus
Gaussian noise, and written with feedaxis.case.write_case in the data format.
"""
from __future__ import annotations

import numpy as np

from feedaxis.case import write_case
from feedaxis.examples import write_table2_case
from feedaxis.physics import geometry, motor, thermal
from feedaxis.physics.mounting import screw_coordinate_m

MICRO_AXIS = {"name": "micro", "screw": {"lead_mm": 1.0},
              "motor": {"step_angle_deg": 0.72, "error_period_steps": 10}}
MICRO_TRUTH = {"lead_error": {"offset_um": 0.25, "slope_um_per_mm": -0.51},
               "assembly_eccentricity": {"cos_um": 0.20, "sin_um": 0.15},
               "motor_step_error": {"harmonic1_cos_um": 0.12, "harmonic1_sin_um": 0.09}}
MICRO_NOISE_UM = 0.05

# A slender cantilevered screw, exaggerated so that its sag is well above the noise.
LONG_AXIS = {"name": "long", "screw": {
    "lead_mm": 10.0, "length_m": 1.5, "diameter_m": 0.02, "density_kg_m3": 7800.0,
    "youngs_modulus_Pa": 2.1e11, "support": "fixed-free", "fixed_end_mm": -100.0}}
LONG_NOISE_UM = 0.5

ISO_AXIS = {"name": "iso", "screw": {"lead_mm": 10.0, "expansion_per_K": 11.7e-6,
                                     "fixed_end_mm": -141.0}}
ISO_NOISE_UM = 0.3

THERMAL_NOISE_UM = 1.0


def micro_positions_mm():
    return np.round(np.linspace(0.0, 5.0, 2501), 6)


def micro_error_um(position_mm, effects):
    """Liu 2023-like errors of the named effects (µm)."""
    error_um = np.zeros_like(position_mm)
    if "lead_error" in effects:
        error_um += geometry.lead_error_um(position_mm, 0.25, -0.51)
    if "assembly_eccentricity" in effects:
        error_um += geometry.eccentricity_error_um(position_mm, 1.0, 0.20, 0.15)
    if "motor_step_error" in effects:
        error_um += motor.motor_step_error_um(position_mm, 1.0, 0.72, 10, (0.12,), (0.09,))
    return error_um


def micro_case(folder, effects, seed):
    position_mm = micro_positions_mm()
    noise = np.random.default_rng(seed).normal(0.0, MICRO_NOISE_UM, position_mm.size)
    return write_case(folder, MICRO_AXIS, positioning={
        "target_mm": position_mm, "error_um": micro_error_um(position_mm, effects) + noise})


def long_case(folder, seed, with_sag=True):
    """0-1000 mm every 2 mm on the long screw: lead error plus (optionally) its sag."""
    screw = LONG_AXIS["screw"]
    position_mm = np.linspace(0.0, 1000.0, 501)
    table = geometry.gravity_sag_table(screw["length_m"], screw["diameter_m"],
                                       screw["density_kg_m3"], screw["youngs_modulus_Pa"],
                                       screw["support"])
    error_um = geometry.lead_error_um(position_mm, 1.0, 0.004)
    if with_sag:
        error_um = error_um + geometry.gravity_sag_error_um(
            screw_coordinate_m(position_mm, screw["fixed_end_mm"]), table)
    error_um += np.random.default_rng(seed).normal(0.0, LONG_NOISE_UM, position_mm.size)
    return write_case(folder, LONG_AXIS, positioning={"target_mm": position_mm, "error_um": error_um})


def iso_layout(n_targets=21, n_runs=5, travel_mm=500.0, seed=0):
    """ISO 230-2 targets P_i = (i-1)p + r_i, runs alternating + and - sweeps."""
    rng = np.random.default_rng(seed)
    targets = np.arange(n_targets) * travel_mm / (n_targets - 1) + np.round(rng.uniform(-2, 2, n_targets), 3)
    rows = []
    for run in range(1, n_runs + 1):
        rows += [(t, 1.0, run) for t in targets] + [(t, -1.0, run) for t in targets[::-1]]
    target_mm, direction, run = (np.array(column) for column in zip(*rows))
    return target_mm, direction, run


def iso_case(folder, seed, backlash_um=0.0, ambient_rise_K=0.0):
    """Bidirectional ISO case: lead error, backlash, ambient drift over the runs."""
    target_mm, direction, run = iso_layout()
    ambient_C = 20.5 + ambient_rise_K * np.linspace(0.0, 1.0, target_mm.size)
    error_um = (geometry.lead_error_um(target_mm, 1.5, -0.012)
                + geometry.backlash_error_um(direction, backlash_um)
                + np.random.default_rng(seed).normal(0.0, ISO_NOISE_UM, target_mm.size))
    if ambient_rise_K:
        params = thermal.ThermalScrewParams(expansion_per_K=11.7e-6, fixed_end_mm=-141.0)
        error_um += thermal.thermal_error_um(params, np.zeros(params.n_cells), target_mm,
                                             ambient_C - 20.0)
    columns = {"target_mm": target_mm, "error_um": error_um, "direction": direction, "run": run}
    if ambient_rise_K:
        columns["ambient_C"] = ambient_C
    return write_case(folder, ISO_AXIS, positioning=columns)


def staggered_case(folder, seed, eccentricity_um, noise_um, first_mm=0.0):
    """81 targets 4.9 mm apart from ``first_mm`` (each staggered by up to ±0.5 mm), a 10 mm
    lead, 3 bidirectional cycles: lead error 2 µm - 0.02 µm/mm, the eccentricity
    (cos, sin) ``eccentricity_um``, B = 4 µm and Gaussian noise; the case folder."""
    rng = np.random.default_rng(seed)
    targets = np.sort(first_mm + 4.9 * np.arange(81) + rng.uniform(-0.5, 0.5, 81))
    columns = {"target_mm": [], "error_um": [], "direction": [], "run": []}
    for run in (1, 2, 3):
        for direction in (1.0, -1.0):
            error = (geometry.lead_error_um(targets, 2.0, -0.02)
                     + geometry.eccentricity_error_um(targets, 10.0, *eccentricity_um)
                     + geometry.backlash_error_um(direction, 4.0)
                     + rng.normal(0.0, noise_um, targets.size))
            for name, values in zip(columns, (targets, error, np.full(81, direction),
                                              np.full(81, run))):
                columns[name] += list(values)
    return write_case(folder, {"name": "staggered", "screw": {"lead_mm": 10.0}},
                      positioning={k: np.array(v) for k, v in columns.items()})


def thermal_case(folder, seed, feed_mm_min=6000.0, params=None):
    """Rong et al. 2023 Table 2 test with a lead error, from feedaxis.examples (physics + noise)."""
    return write_table2_case(folder, feed_mm_min, params, noise_um=THERMAL_NOISE_UM, seed=seed)


def in_memory_case(axis_values, **columns):
    """A Case held in memory (no folder written), for the many generated trials."""
    from pathlib import Path

    from feedaxis.case import Axis, Case
    from feedaxis.measurement.positioning import PositioningSamples

    has_direction = "direction" in columns
    direction = columns.pop("direction", np.ones_like(columns["target_mm"]))
    axis = Axis(axis_values["name"], axis_values["screw"], axis_values.get("motor", {}))
    return Case(Path("generated"), axis, {"positioning": PositioningSamples(
        direction=direction, has_direction=has_direction, **columns)})


def run_clock(run):
    """Run number plus the sample's place in its run (the order of the rows)."""
    clock = np.empty(run.size)
    for value in np.unique(run):
        members = np.flatnonzero(run == value)
        clock[members] = value + np.arange(members.size) / members.size
    return clock


def iso_trial(rng, backlash_um=0.0, noise_um=ISO_NOISE_UM, drift_um_per_run=0.0, outliers=0,
              shape_um=0.0, outlier_um=3.0):
    """An ISO 230-2 case (21 targets x 5 bidirectional runs): lead error, an optional
    per-target shape (random, standard deviation ``shape_um``), backlash, a drift linear in
    the run order, white noise and ``outliers`` isolated spikes; (case, outlier indices)."""
    target_mm, direction, run = iso_layout()
    _, target_index = np.unique(target_mm, return_inverse=True)
    error_um = (geometry.lead_error_um(target_mm, 1.5, -0.012)
                + rng.normal(0.0, shape_um, target_index.max() + 1)[target_index]
                + geometry.backlash_error_um(direction, backlash_um)
                + drift_um_per_run * (run_clock(run) - 1.0)
                + rng.normal(0.0, noise_um, target_mm.size))
    spikes = rng.choice(target_mm.size, outliers, replace=False)
    error_um[spikes] += outlier_um * rng.choice((-1.0, 1.0), outliers)
    return in_memory_case(ISO_AXIS, target_mm=target_mm, error_um=error_um, direction=direction,
                          run=run), np.sort(spikes)


def scan_trial(rng, noise_um=ISO_NOISE_UM, drift_um=0.0, outliers=0, outlier_um=3.0):
    """A dense single-pass scan, 0-500 mm every 1 mm: lead error, a slow drift over the pass
    (linear in time, which a single pass cannot tell from a lead error), white noise and
    ``outliers`` spikes; (case, outlier indices)."""
    target_mm = np.arange(0.0, 501.0, 1.0)
    error_um = (geometry.lead_error_um(target_mm, 1.5, -0.012)
                + drift_um * target_mm / target_mm[-1]
                + rng.normal(0.0, noise_um, target_mm.size))
    spikes = rng.choice(target_mm.size, outliers, replace=False)
    error_um[spikes] += outlier_um * rng.choice((-1.0, 1.0), outliers)
    return in_memory_case(ISO_AXIS, target_mm=target_mm, error_um=error_um), np.sort(spikes)


def paired_t_p_value(case):
    """Two-sided p-value of a plain paired t-test of x(+) - x(-) at each target and run."""
    from scipy import stats

    p = case.positioning
    up, down = p.direction > 0, p.direction < 0
    key_up = np.lexsort((p.target_mm[up], p.run[up]))
    key_down = np.lexsort((p.target_mm[down], p.run[down]))
    return float(stats.ttest_rel(p.error_um[up][key_up], p.error_um[down][key_down]).pvalue)


def noise_um(rng, size, kind, sigma_um=ISO_NOISE_UM):
    """Measurement noise of one null family in the order taken (µm): ``white`` Gaussian,
    ``ar0.5`` / ``ar0.9`` / ``ar0.95`` AR(1) with that correlation between neighbouring
    samples (marginal σ), ``t3`` Student-t with 3 degrees of freedom scaled to σ,
    ``quantised`` Gaussian rounded to 0.1 µm."""
    if kind.startswith("ar"):
        rho = float(kind[2:])
        innovations = rng.normal(0.0, sigma_um * np.sqrt(1 - rho ** 2), size)
        noise = np.empty(size)
        noise[0] = rng.normal(0.0, sigma_um)
        for i in range(1, size):
            noise[i] = rho * noise[i - 1] + innovations[i]
        return noise
    if kind == "t3":
        return sigma_um * rng.standard_t(3, size) / np.sqrt(3.0)
    noise = rng.normal(0.0, sigma_um, size)
    return np.round(noise, 1) if kind == "quantised" else noise


def null_trial(rng, layout, noise="white", drift=False, outliers=0):
    """A null case of ``layout`` ("iso": 21 targets x 5 bidirectional runs; "scan": a dense
    single pass every 1 mm over 500 mm, with time stamps) whose model is the truth (lead
    error), with the noise family ``noise`` in the order taken, optionally a drift along
    the test's clock and ``outliers`` spikes of ±3 µm; (case, spike indices)."""
    if layout == "iso":
        target_mm, direction, run = iso_layout()
        columns = {"direction": direction, "run": run}
        clock = run_clock(run) - 1.0
        drift_um = 0.05 * clock
    else:
        target_mm = np.arange(0.0, 501.0, 1.0)
        columns = {"time_s": target_mm * 0.5}
        drift_um = 1.0 * target_mm / target_mm[-1]
    error_um = (geometry.lead_error_um(target_mm, 1.5, -0.012)
                + noise_um(rng, target_mm.size, noise) + (drift_um if drift else 0.0))
    spikes = rng.choice(target_mm.size, outliers, replace=False)
    error_um[spikes] += 3.0 * rng.choice((-1.0, 1.0), outliers)
    return in_memory_case(ISO_AXIS, target_mm=target_mm, error_um=error_um, **columns), \
        np.sort(spikes)


NULL_FAMILIES = {f"{layout}, {label}": (layout, options)
                 for layout in ("iso", "scan")
                 for label, options in (("white", {}), ("AR(1) 0.5", {"noise": "ar0.5"}),
                                        ("AR(1) 0.9", {"noise": "ar0.9"}),
                                        ("AR(1) 0.95", {"noise": "ar0.95"}),
                                        ("Student-t 3", {"noise": "t3"}),
                                        ("quantised 0.1 um", {"noise": "quantised"}),
                                        ("drifting", {"drift": True}),
                                        ("2 outliers", {"outliers": 2}))}


def names_something(diagnosis, drift_allowed=False):
    """A false alarm on a null: an effect named, or a structure (a drift only where the
    null drifts); outliers, transients and an ``undetermined`` verdict are not alarms."""
    return bool(diagnosis.candidates) or any(
        not (drift_allowed and s.kind == "drift") for s in diagnosis.unexplained)


NULL_LAYOUTS = {
    "ISO 230-2 repeats": lambda rng: iso_trial(rng, drift_um_per_run=0.05, outliers=2),
    "dense single-pass scan": lambda rng: scan_trial(rng, drift_um=1.0, outliers=2),
}


def false_alarm(diagnosis, spikes):
    """True when a null diagnosis names an effect or a structure (a drift is really there)
    or misses or invents an outlier (rows are 1-based, header = row 1)."""
    return (bool(diagnosis.candidates) or any(s.kind != "drift" for s in diagnosis.unexplained)
            or diagnosis.outlier_rows != [int(i) + 2 for i in spikes])


def backlash_power(diagnose, model, backlash_um, trials, seed):
    """(share of trials naming backlash, share with a paired t-test p < 0.001)."""
    rng = np.random.default_rng(seed)
    named = t_test = 0
    for _ in range(trials):
        case, _ = iso_trial(rng, backlash_um=backlash_um)
        named += [c.effect for c in diagnose(case, model).candidates][:1] == ["backlash"]
        t_test += paired_t_p_value(case) < 1e-3
    return named / trials, t_test / trials


# One + and one - pass per target, the shapes of real acceptance tests (issue 33): the
# families the single-pass benchmark and tests/fit_diagnosis/test_single_pass.py use.
# trend_um: the lead error's change over the travel; pair_scatter_um: the standard
# deviation of the + reading less the - reading at a target (noise alone).
SINGLE_PASS_FAMILIES = {
    "null, white, 11 targets": dict(n_targets=11),
    "null, white, 15 targets": dict(n_targets=15),
    "null, white, 21 targets": dict(n_targets=21),
    "null, Student-t (3), 15 targets": dict(noise="t3"),
    "null, AR(1) 0.5 in time, 15 targets": dict(noise="ar0.5"),
    "null, AR(1) 0.8 in time, 21 targets": dict(n_targets=21, noise="ar0.8"),
    "null, reversal random per target": dict(reversal_spread_um=4.0),
    "null, reversal changing 8 µm, 21 targets": dict(n_targets=21, reversal_change_um=8.0),
    "null, a bow of 8 µm": dict(bow_um=8.0),
    "trend, 11 unequal targets": dict(n_targets=11, trend_um=-16.9, unequal=True),
    "trend + bow, AR(1) 0.8 in time": dict(trend_um=-16.9, bow_um=6.0, noise="ar0.8"),
    "trend + bow, reversal changing 8 µm": dict(trend_um=-16.9, bow_um=6.0,
                                                reversal_change_um=8.0),
    "trend, reversal changing 12 µm, 21 targets": dict(n_targets=21, trend_um=-16.9,
                                                       reversal_change_um=12.0),
    "trend + bow, 17 unequal, t(3), zero at 12 µm": dict(
        n_targets=17, trend_um=-16.9, bow_um=5.0, unequal=True, noise="t3",
        reversal_spread_um=3.0, zero_um=12.0),
}


def single_pass_trial(rng, n_targets=15, travel_mm=600.0, trend_um=0.0, bow_um=0.0,
                      pair_scatter_um=4.1, reversal_um=3.0, reversal_spread_um=0.0,
                      reversal_change_um=0.0, noise="white", unequal=False, zero_um=None):
    """An acceptance test of one + pass then one - pass over ``n_targets`` targets
    (evenly spaced with ±3 mm jitter, or ``unequal``: uniform at random between both ends):
    a lead error changing ``trend_um`` over the travel, a bow of ``bow_um`` at mid-travel,
    a reversal of ``reversal_um`` changing by ``reversal_change_um`` along the travel and
    scattering ``reversal_spread_um`` from target to target, noise of the family ``noise``
    (:func:`noise_um`) in the order taken with the pairs scattering ``pair_scatter_um``;
    the deviations referenced to their mean, or with the first reading at ``zero_um``."""
    if unequal:
        inner = rng.uniform(0.0, travel_mm, n_targets - 2)
    else:
        inner = np.linspace(0.0, travel_mm, n_targets)[1:-1] + rng.uniform(-3, 3, n_targets - 2)
    targets = np.round(np.sort(np.concatenate(([0.0, travel_mm], inner))), 3)
    fraction = targets / travel_mm
    systematic = (geometry.lead_error_um(targets, 0.0, trend_um / travel_mm)
                  + bow_um * 4 * fraction * (1 - fraction))
    reversal = (reversal_um + reversal_change_um * (fraction - 0.5)
                + rng.normal(0.0, reversal_spread_um, n_targets))
    noise = noise_um(rng, 2 * n_targets, noise, pair_scatter_um / np.sqrt(2))
    error_um = np.concatenate([systematic + reversal / 2 + noise[:n_targets],
                               (systematic - reversal / 2)[::-1] + noise[n_targets:]])
    error_um -= error_um[0] - zero_um if zero_um is not None else error_um.mean()
    return in_memory_case(ISO_AXIS, target_mm=np.concatenate([targets, targets[::-1]]),
                          error_um=error_um, direction=np.repeat([1.0, -1.0], n_targets),
                          run=np.ones(2 * n_targets))
