"""ISO 230-2 figures against a hand-computed example; compare, report, effects and demo
through the CLI; the fitted model replayed through the FMUs."""
import json
import math

import numpy as np
import pytest

import synthetic as syn
from feedaxis.case import read_case
from feedaxis.measurement.positioning import PositioningSamples as Positioning
from feedaxis.cli import main
from feedaxis.cosim.replay import replay_positioning
from feedaxis.effects import CATALOG, Model
from feedaxis.fit import fit
from feedaxis.iso230 import iso230_figures, target_clusters, target_groups

ROOT2 = math.sqrt(2.0)


def test_iso230_figures_match_the_hand_computed_example():
    # targets 0, 10, 20; two runs each way.
    #   up:   (1, 2) (3, 3) (0, 1)  -> means 1.5, 3, 0.5;  s = √2/2, 0, √2/2
    #   down: (-1, 0) (2, 4) (1, 1) -> means -0.5, 3, 1;   s = √2/2, √2, 0
    target = np.array([0, 10, 20, 0, 10, 20, 20, 10, 0, 20, 10, 0], float)
    error = np.array([1, 3, 0, 2, 3, 1, 1, 2, -1, 1, 4, 0], float)
    direction = np.array([1] * 6 + [-1] * 6, float)
    s = ROOT2 / 2
    figures = iso230_figures(target, error, direction)
    expected = {
        "B_um": 2.0, "B_mean_um": 0.5,                 # B_i = 2, 0, -0.5
        "M_um": 2.5,                                   # x̄_i = 0.5, 3, 0.75
        "E_up_um": 2.5, "E_down_um": 3.5, "E_um": 3.5,
        "R_up_um": 4 * s, "R_down_um": 4 * ROOT2,
        "R_um": 4 * ROOT2,                             # max(2s+2s+2, 0+2√2+0 vs 4√2, ...)
        "A_up_um": 3 - (0.5 - 2 * s),                  # 3 - (-0.914)
        "A_down_um": (3 + 2 * ROOT2) - (-0.5 - 2 * s),
        "A_um": (3 + 2 * ROOT2) - (-0.5 - 2 * s),
    }
    for key, value in expected.items():
        assert figures[key] == pytest.approx(value, abs=1e-12), key
    assert figures["targets"] == 3 and figures["runs_up"] == 2 and figures["runs_down"] == 2


def test_recorded_target_jitter_does_not_split_targets():
    """Targets recorded with ±50 nm jitter (a laser system logging the position it reached)
    give the figures, targets, runs and groups of the exact targets; targets 0.2 µm apart
    stay two targets."""
    rng = np.random.default_rng(7)
    exact = np.tile(np.repeat(np.linspace(0.0, 100.0, 11), 5), 2)
    direction = np.repeat([1.0, -1.0], 55)
    error = 0.5 * direction + 0.02 * exact + rng.normal(0.0, 0.1, exact.size)
    jittered = exact + rng.uniform(-5e-5, 5e-5, exact.size)
    expected = iso230_figures(exact, error, direction)
    got = iso230_figures(jittered, error, direction)
    assert got.keys() == expected.keys() and "R_um" in got and got["targets"] == 11
    for key, value in expected.items():
        assert got[key] == pytest.approx(value, abs=1e-12), key

    def groups(target_mm):
        return target_groups(Positioning(target_mm, error, direction, has_direction=True))
    np.testing.assert_array_equal(groups(jittered), groups(exact))
    assert target_clusters([0.0, 2e-4])[0].size == 2


def test_unidirectional_single_run_gives_only_what_it_can():
    figures = iso230_figures([0, 1, 2], [0.0, 1.0, -1.0], [1, 1, 1])
    assert figures["E_up_um"] == 2.0
    assert "R_up_um" not in figures and "B_um" not in figures


def test_compare_shows_how_much_the_model_explains(tmp_path, capsys):
    folder = syn.iso_case(tmp_path / "case", seed=31, backlash_um=-4.0)
    model = tmp_path / "m.toml"
    assert main(["fit", str(folder), "--add", "lead_error", "--add", "backlash",
                 "--out", str(model)]) == 0
    capsys.readouterr()
    assert main(["compare", str(folder), "--model", str(model), "--json"]) == 0
    comparison = json.loads(capsys.readouterr().out)
    figures = comparison["figures"]
    assert comparison["bidirectional"] and comparison["runs_up"] == 5
    assert figures["B_um"]["measured_um"] == pytest.approx(4.0, abs=0.5)
    assert figures["B_um"]["explained"] > 0.8
    assert figures["E_um"]["residual_um"] < 0.3 * figures["E_um"]["measured_um"]
    assert figures["R_um"]["residual_um"] < figures["R_um"]["measured_um"]
    assert main(["compare", str(folder)]) == 0
    assert "reversal B" in capsys.readouterr().out


def test_report_is_one_self_contained_html_page(tmp_path, capsys):
    folder = syn.iso_case(tmp_path / "case", seed=32, backlash_um=-4.0)
    model = tmp_path / "m.toml"
    main(["fit", str(folder), "--add", "lead_error", "--add", "backlash", "--out", str(model)])
    out = tmp_path / "r" / "report.html"
    assert main(["report", str(folder), "--model", str(model), "--out", str(out)]) == 0
    page = out.read_text()
    assert page.count("data:image/png;base64,") == 8   # with the ISO 230-2 deviation plot
    for heading in ("Measurement against model", "Residual", "Each effect's contribution",
                    "Error ladder", "ISO 230-2 figures", "verdict: adequate", "Compensation table",
                    'alt="ISO 230-2 deviation"'):
        assert heading in page
    assert 'src="http' not in page


def test_report_defaults_to_the_empty_model_like_fit_and_diagnose(tmp_path, capsys):
    folder = syn.iso_case(tmp_path / "case", seed=33, backlash_um=-4.0)
    out = tmp_path / "report.html"
    assert main(["report", str(folder), "--out", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == {"report": str(out)}
    page = out.read_text()
    assert "verdict: missing_effect" in page and "lead_error" in page


def test_report_names_what_a_metrologist_signs(tmp_path):
    """Date, version, case and model on the page; uncertainties in the parameter table,
    which are the fit's own; µm, never um."""
    import re

    from feedaxis import __version__
    from feedaxis.case import read_case
    from feedaxis.measurement.positioning import PositioningSamples as Positioning
    from feedaxis.effects import CATALOG, Model
    from feedaxis.fit import fit

    folder = syn.iso_case(tmp_path / "case", seed=32, backlash_um=-4.0)
    fitted = fit(Model([CATALOG["lead_error"], CATALOG["backlash"]]), read_case(folder))
    model = tmp_path / "m.toml"
    model.write_text(fitted.model.to_toml())
    out = tmp_path / "r.html"
    assert main(["report", str(folder), "--model", str(model), "--out", str(out)]) == 0
    page = out.read_text()
    assert f"feedaxis {__version__}" in page and re.search(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC", page)
    assert str(folder) in page and "lead_error + backlash" in page
    sigma = fitted.uncertainties["backlash"]["backlash_um"]
    row = re.search(r"<td>backlash.backlash_um</td><td[^>]*>[^<]*</td><td[^>]*>([^<]*)</td>"
                    r"<td[^>]*>([^<]*)</td>", page)
    assert float(row.group(1)) == pytest.approx(sigma, rel=0.05) and row.group(2) == "µm"
    assert ">um<" not in page and " um " not in page


def test_effects_command_lists_the_catalog(capsys):
    assert main(["effects", "--json"]) == 0
    catalog = json.loads(capsys.readouterr().out)
    assert list(catalog) == ["lead_error", "gravity_sag", "assembly_eccentricity",
                             "motor_step_error", "backlash", "thermal_screw", "ambient_expansion",
                             "servo_plant", "coulomb_friction", "viscous_friction",
                             "stribeck_friction", "constant_force"]
    assert catalog["backlash"]["parameters"]["backlash_um"]["unit"] == "um"


@pytest.fixture(scope="module")
def position_fmus(tmp_path_factory):
    from feedaxis.fmu_build import build_fmus
    out = tmp_path_factory.mktemp("fmus")
    return {p.stem: p for p in build_fmus(out, ("GeometricError", "StepperError"))}


@pytest.mark.parametrize("kind", ["micro", "iso", "long"])
def test_fitted_model_through_the_fmus_equals_the_library(tmp_path, position_fmus, kind):
    writers = {"micro": (lambda f: syn.micro_case(f, syn.MICRO_TRUTH, seed=1),
                         ("lead_error", "assembly_eccentricity", "motor_step_error")),
               "iso": (lambda f: syn.iso_case(f, seed=2, backlash_um=-4.0),
                       ("lead_error", "backlash", "assembly_eccentricity")),
               "long": (lambda f: syn.long_case(f, seed=3), ("lead_error", "gravity_sag"))}
    write, names = writers[kind]
    case = read_case(write(tmp_path / "case"))
    model = fit(Model([CATALOG[n] for n in names]), case).model
    through_fmus = replay_positioning(case, model, position_fmus)
    predicted = model.predict_um(case)
    assert np.max(np.abs(predicted)) > 0.1
    np.testing.assert_allclose(through_fmus, predicted, rtol=1e-12, atol=1e-12)


def test_demo_runs_the_loop_to_adequate(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert [r.get("added") for r in summary["rounds"]] == [
        "lead_error", "assembly_eccentricity", "motor_step_error", None]
    assert summary["rounds"][-1]["verdict"] == "adequate"
    assert summary["rounds"][-1]["rms_um"] < 1.3 * 0.05
    assert summary["fmu_max_difference_um"] < 1e-9
    assert (tmp_path / "report.html").exists() and (tmp_path / "model.toml").exists()
    # the case and the laser example are copied where the demo says
    assert summary["case"] == str(tmp_path / "case")
    assert read_case(tmp_path / "case").positioning.size == 2501
    assert sorted(p.name for p in (tmp_path / "laser-example").iterdir()) == [
        "X-axis.rtl", "axis.toml"]
    readme_says_how_far_the_fit_is_from_the_truth(read_case(tmp_path / "case"),
                                                  tmp_path / "model.toml")


def readme_says_how_far_the_fit_is_from_the_truth(case, model_path):
    """The README's sentence on the demo's fitted values gives each one's distance from the
    value the case was generated from, in standard uncertainties, as the fit has it."""
    import re
    from pathlib import Path

    from feedaxis.effects import CATALOG, load_model
    from feedaxis.examples import SEED001_ECCENTRICITY, SEED001_LEAD, SEED001_MOTOR
    from feedaxis.fit import fit

    result = fit(load_model(model_path, CATALOG), case)
    truth = [("lead_error", "slope_um_per_mm", SEED001_LEAD["slope_um_per_mm"]),
             ("assembly_eccentricity", "cos_um", SEED001_ECCENTRICITY["cos_um"]),
             ("assembly_eccentricity", "sin_um", SEED001_ECCENTRICITY["sin_um"]),
             ("motor_step_error", "harmonic1_cos_um", SEED001_MOTOR["cos_um"]),
             ("motor_step_error", "harmonic1_sin_um", SEED001_MOTOR["sin_um"])]
    distances = [f"{abs(result.model.values[e][p] - t) / result.uncertainties[e][p]:.1f}"
                 for e, p, t in truth]
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
    sentence = re.sub(r"\s+", " ", readme.split("The fitted values come back", 1)[1]
                      .split("The demo leaves", 1)[0])
    quoted = re.findall(r"(\d\.\d)(?= standard uncertainties off| and | off)", sentence)
    assert quoted == distances, sentence


def test_bundled_case_is_the_documented_reconstruction(tmp_path):
    from feedaxis.examples import BUNDLED_CASE, write_seed001_case
    fresh = read_case(write_seed001_case(tmp_path / "fresh"))
    bundled = read_case(BUNDLED_CASE)
    np.testing.assert_allclose(bundled.positioning.error_um, fresh.positioning.error_um, atol=1e-5)
