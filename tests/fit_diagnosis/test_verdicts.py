"""Verdicts on the data engineers really have (issue 20, positioning): single passes each
way, serially correlated noise, sparse irregular targets, an alternation at another
wavelength than the catalog's, drift saved with the fit, an axis that does not repeat,
transients at a scan's ends, shapes in words. Cases from known parameters, seeded; the
false-alarm rates over 200 nulls per family are printed by benchmarks/bench_false_alarms.py,
here a few seeds each, asserted loosely."""
import json

import numpy as np
import pytest

import synthetic as syn
from feedaxis.case import write_case
from feedaxis.cli import main
from feedaxis.diagnose import diagnose
from feedaxis.effects import CATALOG, Model
from feedaxis.fit import fit
from feedaxis.physics import geometry, motor

LEAD = Model([CATALOG["lead_error"]])
SPARSE_AXIS = {"name": "sparse", "screw": {"lead_mm": 5.0},
               "motor": {"step_angle_deg": 1.8, "error_period_steps": 4}}  # motor: 0.1 mm


def single_pass_each_way(rng, slope_um_per_mm=0.6, shape_um=8.0, reversal_um=1.5,
                         noise_um=1.5):
    """An acceptance test: 11 targets over 50 mm, one + pass then one - pass, a lead error,
    a reproducible per-target shape, a constant reversal and noise."""
    targets = np.round(np.linspace(0.0, 50.0, 11) + rng.uniform(-0.3, 0.3, 11), 3)
    shape = rng.normal(0.0, shape_um, 11)
    target_mm = np.concatenate([targets, targets[::-1]])
    direction = np.repeat([1.0, -1.0], 11)
    error_um = (slope_um_per_mm * target_mm + np.concatenate([shape, shape[::-1]])
                + reversal_um / 2 * direction + rng.normal(0.0, noise_um, 22))
    return syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=error_um,
                              direction=direction, run=np.ones(22))


@pytest.mark.parametrize("seed", range(3))
def test_a_single_pass_each_way_names_the_lead_error_and_the_shape(seed):
    """The + and - readings at a target are replicates about a constant reversal: the lead
    error is named against their scatter, and the per-target shape is an irregular error,
    not `adequate`."""
    case = single_pass_each_way(np.random.default_rng(seed))
    found = diagnose(case, Model())
    assert found.candidates[0].effect == "lead_error"
    assert "+ and - readings" in found.noise_source
    fitted = diagnose(case, fit(LEAD + CATALOG["backlash"], case).model)
    assert fitted.verdict == "unexplained"
    assert [s.kind for s in fitted.unexplained] == ["irregular"]


def test_one_pass_one_way_is_undetermined():
    """11 targets, one direction, one pass: the scatter from target to target cannot be told
    from noise; the verdict says so."""
    rng = np.random.default_rng(1)
    target_mm = np.linspace(0.0, 50.0, 11)
    case = syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm,
                              error_um=0.6 * target_mm + rng.normal(0.0, 5.0, 11))
    found = diagnose(case, fit(LEAD, case).model)
    assert found.verdict == "undetermined" and "without replicates" in found.undetermined_reason


@pytest.mark.parametrize("seed", range(4))
def test_dense_scans_with_correlated_noise_name_nothing_and_say_why(seed):
    """2,501 points, AR(1) noise with ρ = 0.9 and σ = 0.1 µm: no effect, no periodic
    structure; the noise is estimated as serially correlated near its σ; one pass cannot
    tell it from an irregular error: undetermined."""
    rng = np.random.default_rng(seed)
    position_mm = syn.micro_positions_mm()
    error_um = (geometry.lead_error_um(position_mm, 0.25, -0.51)
                + syn.noise_um(rng, position_mm.size, "ar0.9", 0.1))
    case = syn.in_memory_case(syn.MICRO_AXIS, target_mm=position_mm, error_um=error_um)
    found = diagnose(case, fit(LEAD, case).model)
    assert found.candidates == [] and found.unexplained == []
    assert found.verdict == "undetermined" and "serially correlated" in found.noise_source
    assert found.noise_um == pytest.approx(0.1, rel=0.35)


def test_sparse_irregular_targets_resolve_the_motor_error_and_the_eccentricity():
    """21 irregular targets over 400 mm, each measured 3 times: a 1.5 µm motor error at
    0.1 mm and a 1 µm eccentricity at the 5 mm lead, both far below the spacing, named with
    their amplitudes within 10 %."""
    rng = np.random.default_rng(4)
    targets = np.sort(rng.uniform(0.0, 400.0, 21)).round(3)
    target_mm = np.repeat(targets, 3)
    error_um = (geometry.lead_error_um(target_mm, 1.0, 0.01)
                + motor.motor_step_error_um(target_mm, 5.0, 1.8, 4, (1.2,), (0.9,))
                + geometry.eccentricity_error_um(target_mm, 5.0, 0.6, 0.8)
                + rng.normal(0.0, 0.1, target_mm.size))
    found = diagnose(syn.in_memory_case(SPARSE_AXIS, target_mm=target_mm, error_um=error_um),
                     LEAD)
    named = [c.effect for c in found.candidates]
    assert set(named) == {"motor_step_error", "assembly_eccentricity"}
    values = found.candidates[-1].result.params()
    assert np.hypot(*values["motor_step_error"].values()) == pytest.approx(1.5, rel=0.1)
    assert np.hypot(*values["assembly_eccentricity"].values()) == pytest.approx(1.0, rel=0.1)


def test_an_alternation_at_another_wavelength_is_no_catalog_effect():
    """Regular targets every 2 mm with a ±4.5 µm alternation between neighbours (4 mm): the
    5 mm lead explains part of it, but the data show their own wavelength; no catalog
    effect is named and the structure is reported at about 4 mm."""
    rng = np.random.default_rng(5)
    target_mm = np.repeat(np.arange(0.0, 100.01, 2.0), 5)
    error_um = 4.5 * np.cos(np.pi * target_mm / 2.0) + rng.normal(0.0, 0.5, target_mm.size)
    found = diagnose(syn.in_memory_case(SPARSE_AXIS, target_mm=target_mm, error_um=error_um),
                     LEAD)
    assert found.candidates == []
    assert found.unexplained[0].kind == "periodic"
    assert found.unexplained[0].wavelength_mm == pytest.approx(4.0, rel=0.02)


def test_the_fit_saves_the_backlash_the_diagnosis_estimates_under_drift(tmp_path, capsys):
    """A drift of 1 µm per run under a -3 µm backlash: the diagnosis fits the drift as a
    nuisance; `fit --add backlash` does the same and saves the same backlash, within 3 %
    of the truth, the drift recorded as a measurement artefact."""
    case, _ = syn.iso_trial(np.random.default_rng(21), backlash_um=-3.0, drift_um_per_run=1.0)
    p = case.positioning
    folder = write_case(tmp_path / "drift", syn.ISO_AXIS, positioning={
        "target_mm": p.target_mm, "error_um": p.error_um, "direction": p.direction,
        "run": p.run})
    named = next(c for c in diagnose(case, LEAD).candidates if c.effect == "backlash")
    model = tmp_path / "m.toml"
    assert main(["fit", str(folder), "--add", "lead_error", "--add", "backlash", "--out",
                 str(model), "--json"]) == 0
    fitted = json.loads(capsys.readouterr().out)
    saved = fitted["params"]["backlash"]["backlash_um"]
    assert saved == pytest.approx(-3.0, rel=0.03)
    assert saved == pytest.approx(named.sizes()["backlash_um"][0], rel=1e-6)
    assert "drift" in fitted["artefacts"]["nuisances"]
    assert "[fit.artefacts.nuisances.drift]" in model.read_text()


def test_an_axis_that_does_not_repeat_is_named_so(capsys, tmp_path):
    """Run-to-run scatter of 20 µm on a 5 µm systematic error: the repeatability R exceeds
    the systematic deviation E; the text and the JSON say the axis does not repeat."""
    case, _ = syn.iso_trial(np.random.default_rng(8), noise_um=20.0)
    found = diagnose(case, LEAD)
    assert found.repeatability["repeatable"] is False
    assert found.repeatability["R_um"] > found.repeatability["E_um"]
    from feedaxis.text import diagnosis_lines
    assert "does not repeat" in diagnosis_lines(found)


def test_the_ends_of_a_continuous_scan_are_transients_not_outliers():
    """A dense pass whose first two and last samples follow the motion's start and stop,
    and one spike in the middle: the ends are transients, the spike an outlier."""
    rng = np.random.default_rng(9)
    position_mm = np.arange(0.0, 200.01, 1.0)
    error_um = 0.01 * position_mm + rng.normal(0.0, 0.1, position_mm.size)
    error_um[[0, 1, -1]] += (4.0, 2.5, -3.0)
    error_um[100] += 3.0
    found = diagnose(syn.in_memory_case(syn.ISO_AXIS, target_mm=position_mm, error_um=error_um,
                                        time_s=position_mm * 0.1), LEAD)
    assert found.transient_rows == [2, 3, position_mm.size + 1]
    assert found.outlier_rows == [102]


def test_a_zigzag_is_not_called_a_trend():
    """Five targets alternating ±10 µm, each measured 5 times: whatever is reported, no
    'trend' (a cubic through five points follows any zig-zag)."""
    rng = np.random.default_rng(10)
    target_mm = np.repeat(np.linspace(0.0, 400.0, 5), 5)
    error_um = 10.0 * np.repeat([1, -1, 1, -1, 1], 5) + rng.normal(0.0, 0.3, target_mm.size)
    found = diagnose(syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=error_um),
                     LEAD)
    assert "trend" not in [s.kind for s in found.unexplained]
    assert found.verdict != "adequate"


@pytest.mark.parametrize("family", [f for f in syn.NULL_FAMILIES if "0.5" not in f])
def test_nulls_of_every_family_name_nothing(family):
    """A few seeds per null family (both layouts; white, AR(1) up to 0.95, Student-t 3,
    quantised, drifting, outliers): at most one false alarm in 8 (the rates over 200 nulls
    each are in benchmarks/bench_false_alarms.py)."""
    layout, options = syn.NULL_FAMILIES[family]
    rng = np.random.default_rng(sorted(syn.NULL_FAMILIES).index(family))
    alarms = sum(syn.names_something(diagnose(syn.null_trial(rng, layout, **options)[0], LEAD),
                                     options.get("drift", False))
                 for _ in range(8))
    assert alarms <= 1
