"""The loop users come for, on data generated from known parameters with seeded noise:
diagnose names the hidden effect, fit --add closes it to the noise, the verdict turns
adequate; nothing is invented on null data; uncatalogued structure is described and a
user effect file closes it."""
import json
from pathlib import Path

import numpy as np
import pytest

import synthetic as syn
from feedaxis.case import read_case
from feedaxis.cli import main
from feedaxis.demo import improve
from feedaxis.diagnose import diagnose
from feedaxis.effects import CATALOG, Model
from feedaxis.examples import write_seed001_case
from feedaxis.fit import fit

MICRO_ALL = ("lead_error", "assembly_eccentricity", "motor_step_error")


def run_json(capsys, *argv):
    assert main([*argv, "--json"]) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


def adds(*names):
    return [arg for name in names for arg in ("--add", name)]


# hidden effect -> (case writer, effects present besides it, true noise level)
HIDDEN = {
    "lead_error": (lambda f: syn.micro_case(f, MICRO_ALL, seed=11), MICRO_ALL, syn.MICRO_NOISE_UM),
    "assembly_eccentricity": (lambda f: syn.micro_case(f, MICRO_ALL, seed=12), MICRO_ALL,
                              syn.MICRO_NOISE_UM),
    "motor_step_error": (lambda f: syn.micro_case(f, MICRO_ALL, seed=13), MICRO_ALL,
                         syn.MICRO_NOISE_UM),
    "gravity_sag": (lambda f: syn.long_case(f, seed=14), ("lead_error", "gravity_sag"),
                    syn.LONG_NOISE_UM),
    "backlash": (lambda f: syn.iso_case(f, seed=15, backlash_um=-4.0), ("lead_error", "backlash"),
                 syn.ISO_NOISE_UM),
    "ambient_expansion": (lambda f: syn.iso_case(f, seed=16, ambient_rise_K=2.0),
                          ("lead_error", "ambient_expansion"), syn.ISO_NOISE_UM),
    "thermal_screw": (lambda f: syn.thermal_case(f, seed=17), ("lead_error", "thermal_screw"),
                      syn.THERMAL_NOISE_UM),
}


@pytest.mark.parametrize("hidden", list(HIDDEN))
def test_hidden_effect_is_named_then_closed(tmp_path, capsys, hidden):
    write, present, noise_um = HIDDEN[hidden]
    case = str(write(tmp_path / "case"))
    start, final = str(tmp_path / "start.toml"), str(tmp_path / "final.toml")
    others = [name for name in present if name != hidden]
    run_json(capsys, "fit", case, *adds(*others), "--out", start)

    diagnosis = run_json(capsys, "diagnose", case, "--model", start)
    assert diagnosis["verdict"] == "missing_effect"
    assert diagnosis["candidates"][0]["effect"] == hidden, diagnosis["candidates"]

    fitted = run_json(capsys, "fit", case, "--model", start, "--add", hidden, "--out", final)
    assert fitted["effects"] == others + [hidden]
    assert fitted["rms_after_um"] <= 1.3 * noise_um < fitted["rms_before_um"]

    after = run_json(capsys, "diagnose", case, "--model", final)
    assert after["verdict"] == "adequate", after
    assert after["candidates"] == [] and after["unexplained"] == []
    assert after["noise_um"] == pytest.approx(noise_um, rel=0.25)


def test_fit_recovers_the_known_parameters(tmp_path):
    case = read_case(syn.micro_case(tmp_path / "case", MICRO_ALL, seed=3))
    result = fit(Model([CATALOG[name] for name in MICRO_ALL]), case)
    for effect, truth in syn.MICRO_TRUTH.items():
        for name, value in truth.items():
            sigma = result.uncertainties[effect][name]
            assert abs(result.model.values[effect][name] - value) < 4 * sigma, (effect, name)
            assert 0 < sigma < 0.01
    s = result.statistics
    assert s.n_points == 2501 and s.n_free == 6 and s.r2 > 0.99
    assert s.bic == pytest.approx(s.n_points * np.log(s.rms_um**2) + 6 * np.log(2501))
    assert s.aic == pytest.approx(s.n_points * np.log(s.rms_um**2) + 12)


def test_chain_from_lead_error_needs_assembly_then_motor(tmp_path):
    case = read_case(syn.micro_case(tmp_path / "case", MICRO_ALL, seed=5))
    model = fit(Model([CATALOG["lead_error"]]), case).model
    final, rounds, _ = improve(case, model, echo=lambda line: None)
    assert [r.get("added") for r in rounds] == ["assembly_eccentricity", "motor_step_error", None]
    assert rounds[-1]["verdict"] == "adequate"
    assert final.names == ("lead_error",) + MICRO_ALL[1:]


def test_null_case_invents_nothing_over_20_seeds(tmp_path):
    verdicts = []
    for seed in range(100, 120):
        case = read_case(syn.micro_case(tmp_path / f"micro{seed}", MICRO_ALL, seed=seed))
        result = diagnose(case, Model([CATALOG[name] for name in MICRO_ALL]))
        verdicts.append((result.verdict, [c.effect for c in result.candidates],
                         [s.kind for s in result.unexplained]))
    assert verdicts == [("adequate", [], [])] * 20


def test_null_iso_case_invents_nothing(tmp_path):
    for seed in range(200, 210):
        case = read_case(syn.iso_case(tmp_path / f"iso{seed}", seed=seed))
        result = diagnose(case, Model([CATALOG["lead_error"]]))
        assert (result.verdict, result.candidates, result.unexplained) == ("adequate", [], [])
        assert result.noise_source == "scatter of repeated samples"


USER_EFFECTS = Path(__file__).resolve().parents[2] / "examples" / "coupling_ripple.py"


def test_uncatalogued_periodic_error_is_described_then_closed_by_a_user_effect(tmp_path, capsys):
    case = str(write_seed001_case(tmp_path / "case", seed=21, ripple=(0.37, 0.2)))
    start, final = str(tmp_path / "start.toml"), str(tmp_path / "final.toml")
    run_json(capsys, "fit", case, *adds(*MICRO_ALL), "--out", start)

    diagnosis = run_json(capsys, "diagnose", case, "--model", start)
    assert diagnosis["verdict"] == "unexplained" and diagnosis["candidates"] == []
    periodic = diagnosis["unexplained"][0]
    assert periodic["kind"] == "periodic"
    assert periodic["wavelength_mm"] == pytest.approx(0.37, rel=0.05)
    assert periodic["amplitude_um"] == pytest.approx(0.2, rel=0.2)

    effects_file = USER_EFFECTS
    named = run_json(capsys, "diagnose", case, "--model", start, "--effects", str(effects_file))
    assert [c["effect"] for c in named["candidates"]] == ["coupling_ripple"]
    fitted = run_json(capsys, "fit", case, "--model", start, "--effects", str(effects_file),
                      "--add", "coupling_ripple", "--out", final)
    assert fitted["rms_after_um"] <= 1.3 * syn.MICRO_NOISE_UM
    after = run_json(capsys, "diagnose", case, "--model", final, "--effects", str(effects_file))
    assert after["verdict"] == "adequate"


def test_model_file_round_trip(tmp_path):
    case = read_case(syn.micro_case(tmp_path / "case", MICRO_ALL, seed=4))
    model = fit(Model([CATALOG[name] for name in MICRO_ALL]), case).model
    path = tmp_path / "model.toml"
    path.write_text(model.to_toml())
    from feedaxis.effects import load_model
    loaded = load_model(path, CATALOG)
    assert loaded.names == model.names and loaded.values == model.values
    np.testing.assert_array_equal(loaded.predict_um(case), model.predict_um(case))


def test_model_file_keeps_the_fit_record(tmp_path):
    """fit --out saves the covariance and what the data could not determine; the standard
    uncertainties read back equal the fit's."""
    case = syn.micro_case(tmp_path / "case", MICRO_ALL, seed=4)
    out = tmp_path / "m.toml"
    assert main(["fit", str(case), *[a for n in MICRO_ALL for a in ("--add", n)],
                 "--out", str(out)]) == 0
    result = fit(Model([CATALOG[name] for name in MICRO_ALL]), read_case(case))
    from feedaxis.effects import load_model
    record = load_model(out, CATALOG).record
    assert record.parameters == result.model.parameter_keys
    assert record.n_points == result.statistics.n_points and not record.undetermined
    for effect, sigmas in result.uncertainties.items():
        for name, sigma in sigmas.items():
            assert record.standard_uncertainty(f"{effect}.{name}") == pytest.approx(sigma,
                                                                                   rel=1e-9)


@pytest.mark.parametrize("content, message", [
    ("[lead_eror]\noffset_um = 1\n", "unknown effect [lead_eror]"),
    ("[lead_error]\noffset_um = 1\n", "lacks slope_um_per_mm"),
    ("[lead_error]\noffset_um = 1\nslope_um_per_mm = 0\ngain = 2\n", "no parameter 'gain'"),
    ("[lead_error]\noffset_um = 'x'\nslope_um_per_mm = 0\n", "must be a finite number"),
    ("[lead_error]\noffset_um = 1\nslope_um_per_mm = 0\n[fit]\nparameters = ['lead_error.offset_um']"
     "\ncovariance = [[1.0]]\nundetermined = {}\nn_points = 9\nrms_um = 1.0\n",
     "column 'fit.parameters'"),
    ("[lead_error]\noffset_um = 1\nslope_um_per_mm = 0\n[fit]\nparameters = "
     "['lead_error.offset_um', 'lead_error.slope_um_per_mm']\ncovariance = [[1.0, 0], [0, nan]]"
     "\nundetermined = {}\nn_points = 9\nrms_um = 1.0\n", "column 'fit.covariance'"),
])
def test_bad_model_file_exits_2(tmp_path, capsys, content, message):
    case = str(syn.micro_case(tmp_path / "case", MICRO_ALL, seed=4))
    model = tmp_path / "m.toml"
    model.write_text(content)
    assert main(["diagnose", case, "--model", str(model)]) == 2
    assert message in capsys.readouterr().err


def test_unknown_or_unavailable_effect_exits_2(tmp_path, capsys):
    case = str(syn.micro_case(tmp_path / "case", MICRO_ALL, seed=4))
    assert main(["fit", case, "--add", "lead_eror"]) == 2
    assert "unknown effect" in capsys.readouterr().err
    assert main(["fit", case, "--add", "backlash"]) == 2
    assert "'direction' column" in capsys.readouterr().err


def test_repeat_groups_keep_targets_and_directions_apart():
    from feedaxis.measurement.positioning import PositioningSamples as Positioning
    from feedaxis.iso230 import target_groups
    # 0.5 mm approached in - and 0 mm approached in + once shared a group key (4x + dir)
    positioning = Positioning(np.array([0.0, 0.5, 0.0, 0.5]), np.zeros(4),
                              np.array([1.0, -1.0, 1.0, -1.0]), has_direction=True)
    groups = target_groups(positioning)
    assert groups[0] == groups[2] and groups[1] == groups[3] and groups[0] != groups[1]
