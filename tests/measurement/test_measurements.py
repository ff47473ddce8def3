"""One pipeline for every kind of measurement (issue 19): a case holding positioning.csv and
tracking.csv, a model mixing kinds, the loop closing on either kind through the same
commands, the JSON fields of every command kept, and the catalog's contract over the
effects of both kinds."""
import json

import numpy as np
import pytest

import synthetic as syn
from feedaxis.case import read_case, write_case
from feedaxis.cli import main
from feedaxis.effects import CATALOG, Model
from feedaxis.examples import BUNDLED_CASE
from feedaxis.kinds import kinds
from feedaxis.measurement import Tracking, measurement_of
from tracking_synthetic import AXIS as SERVO_AXIS, step_loop, two_sines, write_tracking_case

MICRO_ALL = ("lead_error", "assembly_eccentricity", "motor_step_error")
MICRO_SERVO_AXIS = {**syn.MICRO_AXIS, "servo": SERVO_AXIS["servo"]}


@pytest.fixture(scope="module")
def friction_run():
    return step_loop(two_sines, 2.0, friction_N=1.5)


@pytest.fixture(scope="module")
def both(tmp_path_factory, friction_run):
    """A case with both files: the micro screw's lead error and a trace with 1.5 N of
    hidden Coulomb friction."""
    folder = tmp_path_factory.mktemp("both") / "case"
    position_mm = syn.micro_positions_mm()
    error_um = syn.micro_error_um(position_mm, ("lead_error",)) + np.random.default_rng(
        5).normal(0.0, syn.MICRO_NOISE_UM, position_mm.size)
    time_s, reference_mm, actual_mm = friction_run
    write_case(folder, MICRO_SERVO_AXIS,
               positioning={"target_mm": position_mm, "error_um": error_um},
               tracking={"time_s": time_s, "reference_mm": reference_mm,
                         "actual_mm": actual_mm + 1e-4 * np.random.default_rng(6).normal(
                             size=time_s.size)})
    return str(folder)


def run(capsys, *argv):
    code = main([*argv, "--json"])
    out = capsys.readouterr().out
    return code, json.loads(out)


def test_a_case_with_both_files_is_diagnosed_on_each_with_an_empty_model(both, capsys):
    code, payload = run(capsys, "diagnose", both)
    assert code == 0
    by_kind = {d["measurement"]: d for d in payload["measurements"]}
    assert list(by_kind) == ["positioning", "tracking"]
    assert [c["effect"] for c in by_kind["positioning"]["candidates"]][:1] == ["lead_error"]
    assert "coulomb_friction" in [c["effect"] for c in by_kind["tracking"]["candidates"]]
    assert "acts on positioning.csv" in by_kind["tracking"]["skipped"]["lead_error"]


def test_a_case_with_both_files_follows_the_models_kind(both, capsys, tmp_path):
    model = str(tmp_path / "m.toml")
    code, fitted = run(capsys, "fit", both, "--add", "lead_error", "--out", model)
    assert code == 0 and fitted["measurement"] == "positioning"
    code, diagnosed = run(capsys, "diagnose", both, "--model", model)
    assert code == 0 and diagnosed["measurement"] == "positioning"
    code, compared = run(capsys, "compare", both, "--model", model)
    assert code == 0 and "figures" in compared
    code, fitted = run(capsys, "fit", both, "--add", "coulomb_friction")
    assert code == 0 and fitted["measurement"] == "tracking"
    assert fitted["params"]["coulomb_friction"]["friction_N"] == pytest.approx(1.5, rel=0.1)


def test_a_report_of_both_files_shows_both(both, capsys, tmp_path):
    out = tmp_path / "r.html"
    assert main(["report", both, "--out", str(out)]) == 0
    page = out.read_text(encoding="utf-8")
    assert "Positioning (positioning.csv)" in page and "Tracking (tracking.csv)" in page


@pytest.mark.parametrize("command", ["fit", "diagnose", "compare", "report"])
def test_a_model_mixing_kinds_is_refused_naming_the_effects(both, capsys, tmp_path, command):
    model = tmp_path / "mixed.toml"
    model.write_text("[lead_error]\noffset_um = 0\nslope_um_per_mm = 0\n"
                     "[coulomb_friction]\nfriction_N = 1\n")
    extra = ["--out", str(tmp_path / "r.html")] if command == "report" else []
    assert main([command, both, "--model", str(model), *extra]) == 2
    message = capsys.readouterr().err
    assert "lead_error act on positioning.csv" in message
    assert "coulomb_friction act on tracking.csv" in message
    assert not (tmp_path / "r.html").exists()


def test_fit_add_of_both_kinds_exits_2(both, capsys):
    assert main(["fit", both, "--add", "lead_error", "--add", "coulomb_friction"]) == 2
    assert "mixes kinds of measurement" in capsys.readouterr().err


def test_the_model_names_its_kind_and_a_case_without_it_is_refused(tmp_path, capsys):
    tracking_only = write_tracking_case(tmp_path / "t", step_loop(two_sines, 0.5), 1)
    assert main(["fit", str(tracking_only), "--add", "lead_error"]) == 2
    assert "has no positioning.csv" in capsys.readouterr().err


@pytest.fixture(scope="module")
def tracking_case(tmp_path_factory, friction_run):
    return str(write_tracking_case(tmp_path_factory.mktemp("t") / "c", friction_run, 2))


@pytest.mark.parametrize("kind", ["positioning", "tracking"])
def test_the_loop_closes_on_each_kind(kind, tmp_path, capsys, tracking_case):
    """Diagnose names the hidden effect, fit --add takes the residual to the noise, the
    diagnosis of the fitted model is adequate: the same commands for either kind."""
    if kind == "positioning":
        case, hidden, start = str(syn.micro_case(tmp_path / "c", MICRO_ALL, seed=3)), \
            "motor_step_error", ("lead_error", "assembly_eccentricity")
    else:
        case, hidden, start = tracking_case, "coulomb_friction", ()
    first = str(tmp_path / "first.toml")
    assert main(["fit", case, *[a for name in start for a in ("--add", name)], "--out",
                 first]) == 0
    capsys.readouterr()
    code, diagnosed = run(capsys, "diagnose", case, "--model", first)
    assert code == 0 and diagnosed["candidates"][0]["effect"] == hidden
    final = str(tmp_path / "final.toml")
    code, fitted = run(capsys, "fit", case, "--model", first, "--add", hidden, "--out", final)
    assert code == 0 and fitted["rms_after_um"] < fitted["rms_before_um"]
    code, diagnosed = run(capsys, "diagnose", case, "--model", final)
    assert code == 0 and diagnosed["verdict"] == "adequate"


# The --json fields of every command before issue 19 (superset kept), by kind.
FIT_KEYS = {"rms_before_um", "rms_after_um", "effects", "params", "uncertainties",
            "undetermined", "statistics"}
STATISTICS_KEYS = {"n_points", "n_free", "rms_before_um", "rms_um", "max_um", "pv_um", "r2",
                   "aic", "bic"}
DIAGNOSE_KEYS = {"positioning": {"rms_um", "noise_um", "verdict", "candidates", "unexplained",
                                 "noise_source", "skipped", "outlier_rows", "test",
                                 "family_alpha"},
                 "tracking": {"rms_um", "noise_um", "verdict", "candidates", "unexplained",
                              "noise_source", "skipped"}}
CANDIDATE_KEYS = {"positioning": {"effect", "rms_after_um", "delta_bic", "evidence",
                                  "parameters", "test", "statistic", "dof", "p_value"},
                  "tracking": {"effect", "rms_after_um", "delta_bic", "p_value", "evidence"}}
STRUCTURE_KEYS = {"positioning": {"kind", "wavelength_mm", "amplitude_um", "evidence",
                                  "test", "statistic", "dof", "p_value"},
                  "tracking": {"kind", "frequency_hz", "amplitude_um", "p_value", "evidence"}}
COMPARE_KEYS = {"positioning": {"case", "effects", "targets", "runs_up", "runs_down",
                                "bidirectional", "rms_measured_um", "rms_residual_um",
                                "figures"},
                "tracking": {"case", "kind", "effects", "samples", "after_s",
                             "max_tracking_error_mm", "rms_tracking_error_mm",
                             "residual_max_um", "residual_rms_um"}}


@pytest.mark.parametrize("kind", ["positioning", "tracking"])
def test_every_json_field_of_today_is_kept(kind, capsys, tmp_path, tracking_case):
    case = str(BUNDLED_CASE) if kind == "positioning" else tracking_case
    add = "lead_error" if kind == "positioning" else "servo_plant"
    code, fitted = run(capsys, "fit", case, "--add", add)
    assert code == 0 and FIT_KEYS <= set(fitted)
    assert STATISTICS_KEYS <= set(fitted["statistics"])
    code, diagnosed = run(capsys, "diagnose", case)
    assert code == 0 and DIAGNOSE_KEYS[kind] <= set(diagnosed)
    assert diagnosed["candidates"], "the empty model misses an effect on both cases"
    for candidate in diagnosed["candidates"]:
        assert CANDIDATE_KEYS[kind] <= set(candidate)
    structures = diagnosed["unexplained"] or _structures_of(kind, capsys, tmp_path)
    for structure in structures:
        assert STRUCTURE_KEYS[kind] <= set(structure)
    code, compared = run(capsys, "compare", case)
    assert code == 0 and COMPARE_KEYS[kind] <= set(compared)


def _structures_of(kind, capsys, tmp_path):
    """Unexplained structure of ``kind``: a sinusoid the catalog lacks."""
    if kind == "positioning":
        position_mm = np.linspace(0.0, 100.0, 201)
        folder = write_case(tmp_path / "ripple", syn.ISO_AXIS, positioning={
            "target_mm": position_mm, "error_um": 2.0 * np.sin(2 * np.pi * position_mm / 7.3)
            + np.random.default_rng(1).normal(0, 0.1, position_mm.size)})
    else:
        run_ = step_loop(two_sines, 2.0, force_N=lambda t: 3.0 * np.sin(2 * np.pi * 40.0 * t))
        folder = write_tracking_case(tmp_path / "force", run_, 3)
    code, diagnosed = run(capsys, "diagnose", str(folder))
    assert code == 0 and diagnosed["unexplained"]
    return diagnosed["unexplained"]


def _case_of(kind, tmp_path):
    if kind == "tracking":
        return read_case(write_tracking_case(tmp_path / "t", step_loop(two_sines, 0.5), 1))
    target_mm, direction, run_ = syn.iso_layout(n_targets=11, n_runs=2)
    axis = {**syn.ISO_AXIS, "motor": {"step_angle_deg": 1.8, "error_period_steps": 4},
            "screw": {**syn.ISO_AXIS["screw"], **syn.LONG_AXIS["screw"]}}
    return syn.in_memory_case(axis, target_mm=target_mm, error_um=0 * target_mm,
                              direction=direction, run=run_,
                              ambient_C=20 + np.linspace(0, 3, target_mm.size))


def _inside(effect, case, rng):
    values = {}
    for name, (lower, upper) in effect.bounds(case.axis).items():
        start = getattr(effect, "neutral", {}).get(name, 0.0) or 0.5 * (max(lower, -5.0)
                                                                      + min(upper, 5.0))
        values[name] = float(np.clip(start * rng.uniform(0.8, 1.2), lower, upper))
    return values


@pytest.mark.parametrize("name", [n for n in CATALOG if n != "thermal_screw"])
def test_every_effect_keeps_the_measurement_contract(name, tmp_path):
    """Every catalog effect of either kind: it names a kind; on a case of that kind the
    separable split reproduces the prediction, its contributions are finite, one per
    sample, and an effect acting inside the system contributes nothing at its neutral
    values; the measurement of the other kind refuses it."""
    effect, rng = CATALOG[name], np.random.default_rng(9)
    assert effect.measurement in kinds()
    case = _case_of(effect.measurement, tmp_path)
    measurement = measurement_of(case, effect.measurement)
    assert measurement.unavailable(effect) is None, measurement.unavailable(effect)
    model = Model([effect], {name: _inside(effect, case, rng)})
    base_um, columns_um = measurement.separable(model)(model.values)
    linear = [model.values[name][p] for p in effect.linear]
    np.testing.assert_allclose(base_um + columns_um @ np.array(linear, dtype=float),
                               measurement.predict_um(model), rtol=1e-9, atol=1e-9)
    contribution = measurement.components(model)[name]
    assert contribution.shape == (measurement.size,) and np.all(np.isfinite(contribution))
    if not effect.additive:
        switched_off = measurement.components(model.with_values({name: dict(effect.neutral)}))
        np.testing.assert_allclose(switched_off[name], 0.0, atol=1e-9)
    other = next(k for k in kinds() if k != effect.measurement)
    assert "acts on" in measurement_of(_case_of(other, tmp_path), other).unavailable(effect)


def test_tracking_step_counts_are_computed_once_per_case(tmp_path, monkeypatch):
    """The loop's step counts belong to the samples: computed when the measurement is made,
    never again per simulation."""
    import feedaxis.measurement.tracking as tracking

    case = read_case(write_tracking_case(tmp_path / "c", step_loop(two_sines, 0.5), 1))
    measurement = Tracking(case)
    monkeypatch.setattr(tracking, "step_counts", lambda *a: pytest.fail("recomputed"))
    measurement.predict_um(Model([CATALOG["servo_plant"]], {"servo_plant": dict(
        CATALOG["servo_plant"].neutral)}))
