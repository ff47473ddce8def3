"""The diagnosis on generated cases with known answers: F tests against the pure error at a
family-wise error rate (power against a paired t-test, clean nulls of both layouts), drift by
run order, outliers by row, aliasing passed over, ambient expansion from the fixed end,
stepwise listing, a reversal that changes along the travel, bounded spectrum, the bounded
solve at its bound. The full counts (200 nulls per layout, the power curve) are printed by
benchmarks/bench_false_alarms.py; here fewer trials, asserted loosely."""
import json

import numpy as np
import pytest

import synthetic as syn
from feedaxis import fit as fit_module
from feedaxis.case import write_case
from feedaxis.cli import main
from feedaxis.diagnose import diagnose
from feedaxis.measurement.positioning import marked_wavelengths
from feedaxis.stats.spectrum import residual_spectrum
from feedaxis.stats.spectrum import MAX_FREQUENCIES
from feedaxis.effects import CATALOG, Model
from feedaxis.physics import geometry

LEAD = Model([CATALOG["lead_error"]])


@pytest.mark.parametrize("layout, trials", [("ISO 230-2 repeats", 60),
                                            ("dense single-pass scan", 25)])
def test_nulls_with_drift_and_outliers_name_nothing(layout, trials):
    rng = np.random.default_rng(7)
    alarms = sum(syn.false_alarm(diagnose(case, LEAD), spikes)
                 for case, spikes in (syn.NULL_LAYOUTS[layout](rng) for _ in range(trials)))
    assert alarms <= 1, f"{alarms} false alarms in {trials} nulls"


def test_backlash_power_follows_the_paired_t_test():
    """At B = 0.25 µm (0.3 µm noise, 105 pairs) a paired t-test at p < 0.001 has ~99 %
    power; the F test against the pure error at a family-wise 0.001 keeps up; at B = 0 it
    stays silent."""
    named, t_test = syn.backlash_power(diagnose, LEAD, 0.25, 40, seed=3)
    assert t_test >= 0.9 and named >= 0.9 * t_test
    assert syn.backlash_power(diagnose, LEAD, 0.0, 20, seed=4)[0] == 0.0


def test_large_reversal_is_named_under_a_large_unmodelled_shape():
    """B = -25 µm under a 20 µm per-target shape the model lacks: named, with its size,
    standard error and F test; the shape is left as irregular."""
    case, _ = syn.iso_trial(np.random.default_rng(11), backlash_um=-25.0, shape_um=20.0)
    result = diagnose(case, LEAD)
    best = result.candidates[0]
    assert best.effect == "backlash" and best.test.p_value < 1e-10
    value, error, unit = best.sizes()["backlash_um"]
    assert abs(value + 25.0) < 4 * error and 0 < error < 0.1 and unit == "um"
    assert "irregular" in [s.kind for s in result.unexplained]


def test_drift_by_run_order_is_a_drift_not_backlash():
    case, _ = syn.iso_trial(np.random.default_rng(12), drift_um_per_run=0.4)
    assert syn.paired_t_p_value(case) < 1e-3  # the drift aliases into the reversal
    result = diagnose(case, LEAD)
    assert result.candidates == []
    drift = [s for s in result.unexplained if s.kind == "drift"]
    assert len(drift) == 1 and "per run" in drift[0].evidence
    per_run = float(drift[0].evidence.split(", ")[1].split(" µm")[0])
    assert per_run == pytest.approx(0.4, rel=0.15)


def test_drift_with_time_is_reported_per_hour(tmp_path, capsys):
    case, _ = syn.iso_trial(np.random.default_rng(13), drift_um_per_run=0.4)
    p = case.positioning
    folder = write_case(tmp_path / "timed", syn.ISO_AXIS, positioning={
        "target_mm": p.target_mm, "error_um": p.error_um, "direction": p.direction,
        "run": p.run, "time_s": 1800.0 * (syn.run_clock(p.run) - 1.0)})  # 30 min per run
    assert main(["diagnose", str(folder), "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    drift = [s for s in payload["unexplained"] if s["kind"] == "drift"]
    assert "per hour" in drift[0]["evidence"] and drift[0]["p_value"] < 1e-6
    assert "backlash" not in [c["effect"] for c in payload["candidates"]]


def test_outliers_are_reported_by_row_and_kept_out(tmp_path, capsys):
    case, spikes = syn.iso_trial(np.random.default_rng(14), outliers=3, outlier_um=4.0)
    p = case.positioning
    folder = write_case(tmp_path / "spikes", syn.ISO_AXIS, positioning={
        "target_mm": p.target_mm, "error_um": p.error_um, "direction": p.direction, "run": p.run})
    assert main(["diagnose", str(folder), "--model", _model_file(tmp_path), "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    rows = [int(i) + 2 for i in spikes]
    assert payload["outlier_rows"] == rows
    assert payload["verdict"] == "adequate" and payload["noise_um"] == pytest.approx(0.3, rel=0.2)
    assert main(["diagnose", str(folder), "--model", _model_file(tmp_path)]) == 0
    assert ", ".join(map(str, rows)) in capsys.readouterr().out


def test_beam_interruptions_in_a_dense_scan_are_outliers_not_structure():
    case, spikes = syn.scan_trial(np.random.default_rng(15), outliers=5, outlier_um=3.0)
    result = diagnose(case, LEAD)
    assert result.outlier_rows == [int(i) + 2 for i in spikes]
    assert (result.verdict, result.unexplained) == ("adequate", [])


def test_wavelengths_the_targets_cannot_resolve_are_passed_over():
    """11 ISO targets 50 mm apart, staggered by 0.09 mm steps: the staggered targets sample
    the phases of the 0.2 mm motor period, but in a regular progression, so a wavelength in
    the band they resolve looks the same at the targets (aliasing): passed over; targets at
    whole multiples of the 10 mm lead all sit at the same phase of the eccentricity: passed
    over."""
    axis = {**syn.ISO_AXIS, "motor": {"step_angle_deg": 0.72, "error_period_steps": 10}}
    target_mm = np.repeat(np.arange(11) * 50.0 + np.round(np.linspace(0, 0.9, 11), 3), 5)
    error_um = geometry.lead_error_um(target_mm, 1.0, 0.2) + np.random.default_rng(16).normal(
        0, 0.3, target_mm.size)
    result = diagnose(syn.in_memory_case(axis, target_mm=target_mm, error_um=error_um), Model())
    assert "cannot tell its 0.2 mm wavelength from" in result.skipped["motor_step_error"]
    assert [c.effect for c in result.candidates] == ["lead_error"]
    same_phase = np.repeat(np.arange(11) * 50.0, 5)
    result = diagnose(syn.in_memory_case(axis, target_mm=same_phase, error_um=error_um), LEAD)
    assert "do not resolve its 10 mm wavelength" in result.skipped["assembly_eccentricity"]


@pytest.mark.parametrize("fixed_end_mm", [-141.0, 151.0])
def test_ambient_expansion_grows_from_the_fixed_end(fixed_end_mm):
    """An axis standing still at each target while the ambient rises 3 K: TE_a =
    α·ΔT·(X - P_f), computed here by hand; named, not a drift, and fitted to the noise."""
    axis = {"name": "z", "screw": {"lead_mm": 10.0, "expansion_per_K": 11.7e-6,
                                   "fixed_end_mm": fixed_end_mm}}
    target_mm, direction, run = syn.iso_layout()
    ambient_C = 20.0 + 3.0 * np.linspace(0.0, 1.0, target_mm.size)
    error_um = (11.7e-6 * (ambient_C - 20.0) * (target_mm - fixed_end_mm) * 1e3
                + np.random.default_rng(17).normal(0.0, 0.3, target_mm.size))
    case = syn.in_memory_case(axis, target_mm=target_mm, error_um=error_um, direction=direction,
                              run=run, ambient_C=ambient_C)
    result = diagnose(case, LEAD)
    assert [c.effect for c in result.candidates] == ["ambient_expansion"]
    fitted = fit_module.fit(LEAD + CATALOG["ambient_expansion"], case)
    assert fitted.rms_um < 1.15 * 0.3
    offset = fitted.model.values["ambient_expansion"]["reference_offset_mm"]
    assert abs(offset) < 4 * fitted.uncertainties["ambient_expansion"]["reference_offset_mm"]


def test_stepwise_lists_only_what_stays_significant(tmp_path):
    """Eccentricity hidden under lead + motor available: the motor ripple soaks up a little
    of it when tried alone, but not on top of the eccentricity, so only that is listed."""
    case = syn.micro_case(tmp_path / "case", ("lead_error", "assembly_eccentricity"), seed=18)
    from feedaxis.case import read_case
    result = diagnose(read_case(case), LEAD)
    assert [c.effect for c in result.candidates] == ["assembly_eccentricity"]


def test_a_reversal_growing_along_the_travel_is_described_as_such():
    target_mm, direction, run = syn.iso_layout()
    reversal_um = 1.0 + 4.0 * target_mm / 500.0  # 1 µm at 0 mm, 5 µm at 500 mm
    error_um = (direction * reversal_um / 2
                + np.random.default_rng(19).normal(0.0, 0.3, target_mm.size))
    case = syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=error_um,
                              direction=direction, run=run)
    result = diagnose(case, LEAD + CATALOG["backlash"])
    structure = next(s for s in result.unexplained if s.kind == "direction")
    change = float(structure.evidence.split("changes by ")[1].split(" µm")[0])
    assert change == pytest.approx(4.0, rel=0.15)


def test_spectrum_of_jittered_targets_is_bounded():
    """110 samples whose recorded targets carry ±1 nm of jitter: the jitter is one target,
    the grid stays within MAX_FREQUENCIES and twice the target spacing."""
    rng = np.random.default_rng(20)
    target_mm = np.tile(np.arange(11) * 50.0, 10) + rng.uniform(-1e-6, 1e-6, 110)
    case = syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=rng.normal(0, 1, 110))
    spectrum = residual_spectrum(case.positioning.target_mm, case.positioning.error_um,
                                 marked_wavelengths(case.axis, CATALOG))
    assert 0 < spectrum.wavelength_mm.size <= MAX_FREQUENCIES
    assert spectrum.wavelength_mm.min() >= 100.0 * (1 - 1e-9)


def test_a_linear_solve_rounding_below_its_bound_is_on_the_bound(monkeypatch):
    """The bounded linear solve may return -1e-17 for a parameter bounded at 0 (a thermal
    test with a rising ambient stopped with 'k4_W_per_mm_min must be >= 0'): clipped."""
    real = fit_module.lsq_linear

    def rounding(*args, **kwargs):
        solution = real(*args, **kwargs)
        lower = kwargs["bounds"][0]
        solution.x = np.where(np.isfinite(lower) & (solution.x <= lower + 1e-12),
                              lower - 1e-17, solution.x)
        return solution

    monkeypatch.setattr(fit_module, "lsq_linear", rounding)
    target_mm = np.linspace(0.0, 100.0, 50)
    case = syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=0.0 * target_mm)
    bounded = Model([_NonNegativeSlope()])
    result = fit_module.fit(bounded, case)
    assert result.model.values["non_negative_slope"]["slope_um_per_mm"] >= 0.0


class _NonNegativeSlope(type(CATALOG["lead_error"])):
    """A lead error whose slope may not go below 0, checked like the physics checks."""

    name = "non_negative_slope"
    parameters = (CATALOG["lead_error"].parameters[0],
                  type(CATALOG["lead_error"].parameters[1])("slope_um_per_mm", "um/mm", 0.0, 1.0))

    def prepare(self, case):
        evaluate = super().prepare(case)

        def checked(values):
            from feedaxis.physics.checks import require_non_negative
            require_non_negative("slope_um_per_mm", values["slope_um_per_mm"])
            return evaluate(values)
        return checked


def _model_file(tmp_path):
    path = tmp_path / "lead.toml"
    path.write_text(LEAD.with_values({"lead_error": {"offset_um": 0.0, "slope_um_per_mm": 0.0}})
                    .to_toml())
    return str(path)


def test_floating_mean_periodogram_matches_scipy_lombscargle():
    from scipy.signal import lombscargle

    from feedaxis.stats.spectrum import floating_mean_amplitude
    rng = np.random.default_rng(21)
    position_mm = np.sort(rng.uniform(0.0, 100.0, 300))
    values_um = 0.3 * np.cos(2 * np.pi * position_mm / 7.0) + 1.0 + rng.normal(0, 0.1, 300)
    frequency = np.linspace(0.01, 1.0, 500)
    ours = floating_mean_amplitude(position_mm, values_um, frequency, chunk_elements=10_000)
    theirs = np.abs(lombscargle(position_mm, values_um, 2 * np.pi * frequency,
                                floating_mean=True, normalize="amplitude"))
    np.testing.assert_allclose(ours, theirs, atol=1e-9)
    assert frequency[np.argmax(ours)] == pytest.approx(1 / 7.0, abs=0.002)


@pytest.mark.parametrize("fixed_end_mm", [-141.0, 151.0])
def test_thermal_fmu_reproduces_the_fitted_ambient_expansion(loaded_fmus, fixed_end_mm):
    """The FMU with ``Model.fmu_parameters`` (offset 37 mm, no heating) gives the effect's
    error at each target and ambient: both call physics.thermal.ambient_error_um."""
    axis = {"name": "z", "screw": {"lead_mm": 10.0, "expansion_per_K": 11.7e-6,
                                   "fixed_end_mm": fixed_end_mm}}
    target_mm = np.linspace(0.0, 500.0, 11)
    ambient_C = np.linspace(19.0, 23.0, 11)
    case = syn.in_memory_case(axis, target_mm=target_mm, error_um=0 * target_mm,
                              ambient_C=ambient_C)
    model = Model([CATALOG["ambient_expansion"]],
                  {"ambient_expansion": {"reference_offset_mm": 37.0}})
    parameters = {**model.fmu_parameters(case.axis)["ThermalScrew"], "k3_W_per_mm_min": 0.0,
                  "k4_W_per_mm_min": 0.0, "fixed_end_mm": fixed_end_mm}
    fmu = loaded_fmus["ThermalScrew"]
    slave = fmu.instantiate("ambient")
    got_um = []
    try:
        fmu.set_values(slave, parameters)
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        for k, (x, ambient) in enumerate(zip(target_mm, ambient_C)):
            fmu.set_values(slave, {"position_mm": float(x), "ambient_C": float(ambient)})
            slave.doStep(float(k), 1.0)
            got_um.append(fmu.get_reals(slave, ["error_um"])[0])
        slave.terminate()
    finally:
        slave.freeInstance()
    expected_um = 11.7e-6 * (ambient_C - 20.0) * (target_mm - fixed_end_mm - 37.0) * 1e3
    np.testing.assert_allclose(model.predict_um(case), expected_um, atol=1e-12)
    np.testing.assert_allclose(got_um, expected_um, atol=1e-9)


def test_drift_is_sized_after_the_reversal_and_shape():
    """Drift 0.3 µm per run under a -2 µm reversal and a 5 µm per-target shape: backlash
    named, the drift sized from the final model."""
    case, _ = syn.iso_trial(np.random.default_rng(22), backlash_um=-2.0, drift_um_per_run=0.3,
                            shape_um=5.0)
    result = diagnose(case, LEAD)
    assert "backlash" in [c.effect for c in result.candidates]
    drift = next(s for s in result.unexplained if s.kind == "drift")
    per_run = float(drift.evidence.split(", ")[1].split(" µm")[0])
    assert per_run == pytest.approx(0.3, rel=0.15)
