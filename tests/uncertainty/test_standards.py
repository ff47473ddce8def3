"""Every standard's figures on a hand-worked 5 targets x 5 bidirectional runs case (every
intermediate value written out), what each standard says the data lack, the CLI's
--standard (default byte-identical to ISO 230-2:2014, `all`, the refusal of an unknown
name), and ISO 230-3's thermal figures against the generating model."""
import json

import numpy as np
import pytest

from feedaxis.cli import main
from feedaxis.iso230 import FIGURE_NAMES, iso230_figures
from feedaxis.standards import NAMES, STANDARDS, UNDEFINED, entries, evaluate, needs
from feedaxis.standards.engine import statistics

TARGETS_MM = np.array([0.0, 101.3, 198.7, 302.1, 400.0])  # unevenly spaced, 400 mm
MEAN_UP = np.array([1.0, 3.0, 2.0, -1.0, 0.0])
STD_UP = np.array([1.0, 0.5, 2.0, 1.0, 0.0])
MEAN_DOWN = np.array([-1.0, 2.0, 3.0, -2.0, 1.0])
STD_DOWN = np.array([0.5, 1.0, 1.0, 0.0, 2.0])
PATTERN = np.array([-1.0, -1.0, 0.0, 1.0, 1.0])  # mean 0, sum of squares 4: s = 1 (n - 1)


def hand_case(runs=PATTERN):
    """Run j goes up over the targets, then down: deviation = mean + s · pattern_j."""
    target, error, direction = [], [], []
    for offset in runs:
        for sign, mean, std, order in ((1.0, MEAN_UP, STD_UP, slice(None)),
                                       (-1.0, MEAN_DOWN, STD_DOWN, slice(None, None, -1))):
            target += list(TARGETS_MM[order])
            error += list((mean + std * offset)[order])
            direction += [sign] * TARGETS_MM.size
    return np.array(target), np.array(error), np.array(direction)


# Worked by hand from the means and standard deviations above:
#   B_i = x̄↑ - x̄↓ = 2, 1, -1, 1, -1        -> B = 2, B̄ = 2/5 = 0.4
#   x̄_i = (x̄↑ + x̄↓)/2 = 0, 2.5, 2.5, -1.5, 0.5 -> M = 2.5 - (-1.5) = 4
#   E↑ = 3 - (-1) = 4; E↓ = 3 - (-2) = 5; E = max(all means) - min = 3 - (-2) = 5
# k = 2 (1997, 2006, 2014; JIS B 6190-2, JIS B 6192, GB/T 17421.2):
#   R_i↑ = 4s↑ = 4, 2, 8, 4, 0 -> R↑ = 8;   R_i↓ = 4s↓ = 2, 4, 4, 0, 8 -> R↓ = 8
#   2s↑ + 2s↓ + |B_i| = 5, 4, 7, 3, 5; R_i = max(that, R_i↑, R_i↓) = 5, 4, 8, 4, 8 -> R = 8
#   x̄↑ + 2s↑ = 3, 4, 6, 1, 0; x̄↑ - 2s↑ = -1, 2, -2, -3, 0         -> A↑ = 6 - (-3) = 9
#   x̄↓ + 2s↓ = 0, 4, 5, -2, 5; x̄↓ - 2s↓ = -2, 0, 1, -2, -3        -> A↓ = 5 - (-3) = 8
#   A = max(6, 5) - min(-3, -3) = 9
ISO_K2 = {"A_um": 9.0, "E_um": 5.0, "M_um": 4.0, "R_um": 8.0, "B_um": 2.0, "B_mean_um": 0.4,
          "E_up_um": 4.0, "E_down_um": 5.0, "R_up_um": 8.0, "R_down_um": 8.0, "A_up_um": 9.0,
          "A_down_um": 8.0}
# k = 3 (ISO 230-2:1988, ±3s):
#   R_i↑ = 6s↑ = 6, 3, 12, 6, 0 -> R↑ = 12;  R_i↓ = 6s↓ = 3, 6, 6, 0, 12 -> R↓ = 12
#   x̄↑ + 3s↑ = 4, 4.5, 8, 2, 0; x̄↑ - 3s↑ = -2, 1.5, -4, -4, 0     -> A↑ = 8 - (-4) = 12
#   x̄↓ + 3s↓ = 0.5, 5, 6, -2, 7; x̄↓ - 3s↓ = -2.5, -1, 0, -2, -5   -> A↓ = 7 - (-5) = 12
#   A = max(8, 7) - min(-4, -5) = 13
ISO_1988 = {"A_um": 13.0, "R_up_um": 12.0, "R_down_um": 12.0, "A_up_um": 12.0,
            "A_down_um": 12.0, "B_um": 2.0, "B_mean_um": 0.4}
# VDI/DGQ 3441: U_i = |B_i| = 2, 1, 1, 1, 1 -> U max = 2, U mean = 6/5 = 1.2
#   s̄_i = (s↑ + s↓)/2 = 0.75, 0.75, 1.5, 0.5, 1;  Ps_i = 6 s̄_i = 4.5, 4.5, 9, 3, 6
#   -> Ps max = 9, Ps mean = 27/5 = 5.4;  Pa = max x̄_i - min x̄_i = 4
#   (U_i + Ps_i)/2 = 3.25, 2.75, 5, 2, 3.5
#   x̄_i + that = 3.25, 5.25, 7.5, 0.5, 4;  x̄_i - that = -3.25, -0.25, -2.5, -3.5, -3
#   P = 7.5 - (-3.5) = 11
VDI = {"P_um": 11.0, "Pa_um": 4.0, "Ps_max_um": 9.0, "Ps_mean_um": 5.4, "U_max_um": 2.0,
       "U_mean_um": 1.2}
EXPECTED = {"iso230-2:2014": ISO_K2, "iso230-2:2006": ISO_K2, "iso230-2:1997": ISO_K2,
            "jis-b6190-2": ISO_K2, "jis-b6192": ISO_K2, "gbt17421.2": ISO_K2,
            "gbt17421.2:2016": ISO_K2,
            "iso230-2:1988": ISO_1988, "vdi3441": VDI}


# A published ISO 230-2 report: the test report of the EPICS ecmc motion-test scripts in
# paulscherrerinstitute/ecmccfg, examples/test/fat_sat/report.md (an axis read at 5 targets,
# 5 runs each way). Deviations (nm) = reference - target position, run j of target i, from
# its input tables; its results as it prints them (mm there, nm here).
ECMC_TARGETS_MM = np.array([-10.0, -4.88, 0.24, 5.36, 10.48])
ECMC_UP_NM = np.array([[-81.02, -102.02, -87.02, -92.02, -100.02],
                       [-87.02, -97.02, -97.02, -95.02, -82.02],
                       [-72.02, -90.02, -88.02, -87.02, -87.02],
                       [-102.02, -86.02, -86.02, -93.02, -78.02],
                       [-100.02, -112.02, -129.02, -109.02, -97.02]])
ECMC_DOWN_NM = np.array([[-99.02, -94.02, -82.02, -91.02, -94.02],
                         [-103.02, -104.02, -95.02, -111.02, -93.02],
                         [-86.02, -102.02, -91.02, -76.02, -99.02],
                         [-72.02, -92.02, -95.02, -103.02, -81.02],
                         [-104.02, -126.02, -130.02, -141.02, -107.02]])
ECMC_REPORT_NM = {  # per target i = 1..5
    "mean_up": [-92.42, -91.62, -84.82, -89.02, -109.42],
    "mean_down": [-92.02, -101.22, -90.82, -88.62, -121.62],
    "mean": [-92.22, -96.42, -87.82, -88.82, -115.52],
    "B_i": [-0.4, 9.6, 6.0, -0.4, 12.2],
    "s_up": [8.79, 6.77, 7.26, 9.0, 12.58], "s_down": [6.28, 7.29, 10.43, 12.18, 15.73],
    "R_i": [35.17, 37.72, 41.7, 48.71, 68.82]}
# Its axis figures that follow ISO 230-2's definitions; its bidirectional E and R lines
# print E↑ (24.6) and max(R↑, R↓) (62.9) instead, so E and R are checked against its own
# per-target table: E = max - min of both columns of means = -84.82 - (-121.62) = 36.8,
# R = max R_i = 68.82.
ECMC_AXIS_NM = {"B_um": 12.2, "B_mean_um": 5.4, "R_up_um": 50.33, "R_down_um": 62.9,
                "E_up_um": 24.6, "E_down_um": 33.0, "M_um": 27.7, "A_up_um": 64.28,
                "A_down_um": 88.81, "A_um": 88.81, "E_um": 36.8, "R_um": 68.82}


def test_a_published_iso230_2_report_is_reproduced():
    """Every per-target value and axis figure of the ecmc report, to the digits it prints
    (0.01 nm), from its raw deviations: its numbers were computed by another program."""
    runs = ECMC_UP_NM.shape[1]
    target = np.concatenate([np.repeat(ECMC_TARGETS_MM, runs)] * 2)
    error_um = np.concatenate([ECMC_UP_NM.ravel(), ECMC_DOWN_NM.ravel()]) / 1000
    direction = np.repeat([1.0, -1.0], ECMC_TARGETS_MM.size * runs)
    _, sides = statistics(target, error_um, direction)
    (_, mean_up, std_up, _), (_, mean_down, std_down, _) = sides["up"], sides["down"]
    reversal = mean_up - mean_down
    found = {"mean_up": mean_up, "mean_down": mean_down, "mean": (mean_up + mean_down) / 2,
             "B_i": reversal, "s_up": std_up, "s_down": std_down,
             "R_i": np.maximum(2 * std_up + 2 * std_down + np.abs(reversal),
                               4 * np.maximum(std_up, std_down))}
    for key, printed in ECMC_REPORT_NM.items():
        assert found[key] * 1000 == pytest.approx(printed, abs=0.0051), key
    figures = evaluate(STANDARDS["iso230-2:2014"], target, error_um, direction)
    assert {key: figures[key] * 1000 for key in ECMC_AXIS_NM} == pytest.approx(
        ECMC_AXIS_NM, abs=0.0051)


def test_the_per_target_statistics_are_the_hand_worked_ones():
    targets, sides = statistics(*hand_case())
    assert targets == 5 and set(sides) == {"up", "down"}
    for label, mean, std in (("up", MEAN_UP, STD_UP), ("down", MEAN_DOWN, STD_DOWN)):
        centres, got_mean, got_std, counts = sides[label]
        np.testing.assert_allclose(centres, TARGETS_MM, atol=1e-12)
        np.testing.assert_allclose(got_mean, mean, atol=1e-12)
        np.testing.assert_allclose(got_std, std, atol=1e-12)
        assert list(counts) == [5] * 5


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_each_standard_gives_the_hand_worked_figures(name):
    figures = evaluate(STANDARDS[name], *hand_case())
    assert list(figures) == list(EXPECTED[name])
    for key, value in EXPECTED[name].items():
        assert figures[key] == pytest.approx(value, abs=1e-12), key
    assert needs(STANDARDS[name], hand_case()[0], hand_case()[2]) == {}


def test_every_positioning_standard_is_defined_or_says_why_not():
    assert set(EXPECTED) == set(STANDARDS)
    for name in UNDEFINED:
        assert name in NAMES
    for standard in STANDARDS.values():
        assert standard.confirmed and standard.unconfirmed
        assert all(standard.title in figure.clause for figure in standard.figures)


def test_the_coverage_factor_is_the_only_difference_between_1988_and_later():
    """Same system two ways: the 1988 figures equal the 2014 formulas with ±3s."""
    target, error, direction = hand_case()
    with_three = iso230_figures(target, error, direction, coverage=3)
    for key, value in evaluate(STANDARDS["iso230-2:1988"], target, error, direction).items():
        assert value == with_three[key]


def test_a_smaller_test_is_said_per_figure_not_silently_computed():
    target, error, direction = hand_case(runs=PATTERN[[0, 2, 4]])  # three runs
    lacking = needs(STANDARDS["vdi3441"], target, direction)
    assert set(lacking) == set(VDI)
    assert lacking["P_um"] == ["5 runs in each direction (VDI/DGQ 3441:1977, five runs in "
                               "each direction); the data have 3"]
    up = direction > 0
    one_way = evaluate(STANDARDS["vdi3441"], target[up], error[up], direction[up])
    assert one_way == {}
    said = needs(STANDARDS["vdi3441"], target[up], direction[up])["P_um"]
    assert said[0] == "both approach directions; the data have + only"
    iso = needs(STANDARDS["iso230-2:2014"], target[up], direction[up])
    assert iso["B_um"][0] == "both approach directions; the data have + only"
    assert iso["E_up_um"][0].startswith("both approach directions (ISO 230-2:2014, the "
                                        "standard test cycle")
    assert iso["E_down_um"][0] == "the - direction; the data lack it"
    even = np.round(target / 100.0) * 100.0
    spacing = needs(STANDARDS["iso230-2:2014"], even, direction)["A_um"]
    assert any("evenly spaced" in item for item in spacing)
    few = needs(STANDARDS["iso230-2:2014"], target * 5, direction)["A_um"]  # 2000 mm, 5 targets
    assert any(item.startswith("at least 10 targets over 2000 mm") for item in few)


def _write_hand_case(folder):
    from feedaxis.case import write_case
    from synthetic import ISO_AXIS

    target, error, direction = hand_case()
    return write_case(folder, ISO_AXIS, positioning={"target_mm": target, "error_um": error,
                                                     "direction": direction})


def _compare(capsys, *args):
    assert main(["compare", *map(str, args), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_the_default_is_iso230_2_2014_byte_identical(tmp_path, capsys):
    import synthetic as syn

    folder = syn.iso_case(tmp_path / "case", seed=31, backlash_um=-4.0)
    default = _compare(capsys, folder)
    named = _compare(capsys, folder, "--standard", "iso230-2:2014")
    assert json.dumps(default["figures"]) == json.dumps(named["figures"])
    assert default["standard"] == "ISO 230-2:2014"
    from feedaxis.case import read_case

    positioning = read_case(folder).positioning
    found = iso230_figures(positioning.target_mm, positioning.error_um, positioning.direction)
    before = entries(FIGURE_NAMES, found, found)  # the empty model: residual = measured
    assert json.dumps(default["figures"]) == json.dumps(
        json.loads(json.dumps(before)))


def test_compare_gives_each_standard_and_all_side_by_side(tmp_path, capsys):
    folder = _write_hand_case(tmp_path / "hand")
    for name, expected in EXPECTED.items():
        payload = _compare(capsys, folder, "--standard", name)
        assert payload["standard"] == STANDARDS[name].title
        assert {key: f["measured_um"] for key, f in payload["figures"].items()} == \
            pytest.approx(expected, abs=1e-9)
        assert set(payload["clauses"]) == set(expected)
    together = _compare(capsys, folder, "--standard", "all")
    assert together["standard"] == "all"
    assert set(together["standards"]) == set(NAMES) - {"all"}
    assert together["standards"]["vdi3441"]["figures"]["P_um"]["measured_um"] == \
        pytest.approx(11.0)
    for name in UNDEFINED:
        block = together["standards"][name]
        assert block["figures"] == {} and "no figures rather than guess" in block["unavailable"]
    assert together["standards"]["iso230-3"]["unavailable"].startswith("not a thermal case")
    assert main(["compare", str(folder), "--standard", "all"]) == 0
    text = capsys.readouterr().out
    assert "VDI/DGQ 3441:1977 figure" in text and "positional uncertainty P" in text


def test_an_unknown_standard_is_refused_naming_it_and_the_allowed_names(tmp_path, capsys):
    folder = _write_hand_case(tmp_path / "hand")
    for command in ("compare", "report", "uncertainty"):
        assert main([command, str(folder), "--standard", "iso230-2:2099"]) == 2
        error = capsys.readouterr().err
        assert "unknown standard 'iso230-2:2099'" in error
        assert all(name in error for name in NAMES)
    assert main(["compare", str(folder), "--standard", "iso230-3"]) == 2
    assert "need a thermal case" in capsys.readouterr().err


def test_the_monte_carlo_propagates_to_every_standard(tmp_path, capsys):
    """Same trials (same seed), figures computed two ways: VDI 3441's Pa is ISO 230-2's M
    and its U max is ISO's B, trial by trial, so their uncertainties are equal; `all`
    gives each standard's entries as the standard alone does."""
    import synthetic as syn

    folder = syn.iso_case(tmp_path / "case", seed=34, backlash_um=-3.0)
    runs = {}
    for name in ("iso230-2:2014", "vdi3441", "iso230-2:1988", "all"):
        assert main(["uncertainty", str(folder), "--trials", "2000", "--seed", "5",
                     "--standard", name, "--json"]) == 0
        runs[name] = json.loads(capsys.readouterr().out)
    iso, vdi, together = runs["iso230-2:2014"]["figures"], runs["vdi3441"]["figures"], \
        runs["all"]["figures"]
    assert runs["vdi3441"]["standard"] == "VDI/DGQ 3441:1977"
    for vdi_key, iso_key in (("Pa_um", "M_um"), ("U_max_um", "B_um")):
        for number in ("value_um", "standard_uncertainty_um", "coverage_interval_um"):
            assert vdi[vdi_key][number] == pytest.approx(iso[iso_key][number], abs=1e-12)
    assert vdi["P_um"]["standard_uncertainty_um"] > 0
    for name in ("iso230-2:2014", "vdi3441", "iso230-2:1988"):
        for key, entry in runs[name]["figures"].items():
            assert together[f"{name}/{key}"]["coverage_interval_um"] == \
                entry["coverage_interval_um"]
    old = runs["iso230-2:1988"]["figures"]["A_um"]["value_um"]
    assert old > iso["A_um"]["value_um"]  # ±3s is wider than ±2s
    assert main(["uncertainty", str(folder), "--standard", "nmtba"]) == 2
    assert "NMTBA" in capsys.readouterr().err
    assert main(["uncertainty", str(folder), "--standard", "iso230-3"]) == 2
    assert "need a thermal case" in capsys.readouterr().err


def test_iso230_3_uncertainty_matches_the_spread_over_repeated_thermal_tests(tmp_path,
                                                                             capsys):
    """A thermal test from known screw parameters with σ = 0.3 µm per reading: the
    per-reading noise the data give is near σ, and the Monte Carlo's standard uncertainty of
    each ISO 230-3 figure (the repeatability alone) is the spread of that figure over 400
    tests generated again from the same model with fresh noise."""
    from feedaxis.case import read_case
    from feedaxis.examples import write_table2_case
    from feedaxis.physics import thermal
    from feedaxis.standards.thermal import ThermalFigures
    from feedaxis.uncertainty.positioning import ReadingNoise

    sigma_um = 0.3
    folder = write_table2_case(tmp_path / "thermal", 6000.0, noise_um=sigma_um, seed=11)
    positioning = read_case(folder).positioning
    noise = ReadingNoise.of(positioning)
    assert noise.sigma_um == pytest.approx(sigma_um, rel=0.25) and noise.dof >= 40
    params = thermal.ThermalScrewParams()
    truth_um = thermal.thermal_error_um(params, thermal.simulate_duty(
        params, thermal.table2_cycle(6000.0, 0.0, 500.0), positioning.time_s),
        positioning.target_mm)
    repeated = truth_um + np.random.default_rng(7).normal(0.0, sigma_um,
                                                          (400, positioning.size))
    figures = ThermalFigures(positioning)
    spread = {key: float(np.std(values, ddof=1)) for key, values in
              figures.of(positioning.target_mm, repeated, positioning.direction).items()}
    assert main(["uncertainty", str(folder), "--standard", "iso230-3", "--trials", "4000",
                 "--seed", "3", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["standard"] == "ISO 230-3:2020" and set(result["figures"]) == set(spread)
    assert result["repeatability"] == noise.source
    for key, entry in result["figures"].items():
        alone = entry["contributions"]["repeatability"]["standard_uncertainty_um"]
        assert alone == pytest.approx(spread[key], rel=0.25), key
        assert entry["standard_uncertainty_um"] >= alone
    drift = result["figures"]["drift_500mm_um"]
    assert drift["contributions"]["setup"]["standard_uncertainty_um"] < 1e-9  # cancels


def test_iso230_3_figures_of_a_seeded_thermal_case_match_the_generating_model(tmp_path,
                                                                              capsys):
    """A thermal test generated from known screw parameters (Rong et al. 2023, Tables 1 and 3) with
    0.05 µm noise: the figures of the measured drifts equal those of the generating model's
    noiseless drifts; a fitted thermal_screw predicts them, and its compensation leaves
    the figures of the measured drift less the model's own predicted drift."""
    from feedaxis.case import read_case
    from feedaxis.compensate import visits
    from feedaxis.effects import Model
    from feedaxis.examples import write_table2_case
    from feedaxis.physics import thermal
    from feedaxis.standards.thermal import thermal_figures

    folder = write_table2_case(tmp_path / "thermal", 6000.0, noise_um=0.05, seed=11)
    case = read_case(folder)
    positioning = case.positioning
    params = thermal.ThermalScrewParams()
    rise_K = thermal.simulate_duty(params, thermal.table2_cycle(6000.0, 0.0, 500.0),
                                   positioning.time_s)
    truth_um = thermal.thermal_error_um(params, rise_K, positioning.target_mm)
    reference = visits(positioning)[1]
    expected = thermal_figures(positioning, truth_um - truth_um[reference])
    assert main(["fit", str(folder), "--add", "lead_error", "--add", "thermal_screw",
                 "--out", str(tmp_path / "m.toml")]) == 0
    capsys.readouterr()
    payload = _compare(capsys, folder, "--standard", "iso230-3", "--model", tmp_path / "m.toml")
    figures = payload["figures"]
    assert payload["standard"] == "ISO 230-3:2020" and set(figures) == set(expected)
    assert {"drift_500mm_um", "expansion_um", "expansion_um_per_m",
            "linear_error_change_um"} <= set(figures)
    for key, (_, value, _, _) in expected.items():
        assert figures[key]["measured_um"] == pytest.approx(value, abs=0.3), key
        assert figures[key]["predicted_um"] == pytest.approx(value, abs=0.1 * abs(value) + 1)
    assert figures["expansion_um_per_m"]["measured_um"] == pytest.approx(
        figures["expansion_um"]["measured_um"] / 0.5)
    from feedaxis.effects import CATALOG
    from feedaxis.effects.files import load_model

    model = load_model(tmp_path / "m.toml", CATALOG)
    thermal_only = Model([e for e in model.effects if e.name == "thermal_screw"], model.values)
    predicted_um = thermal_only.predict_um(case)
    measured_drift = positioning.error_um - positioning.error_um[reference]
    left = thermal_figures(positioning, measured_drift
                           - (predicted_um - predicted_um[reference]))
    for key, (_, value, _, _) in left.items():
        assert figures[key]["compensated_um"] == pytest.approx(value, abs=1e-9), key
    assert abs(figures["expansion_um"]["compensated_um"]) < \
        0.2 * abs(figures["expansion_um"]["measured_um"])
    assert abs(figures["drift_500mm_um"]["compensated_um"]) < \
        0.2 * abs(figures["drift_500mm_um"]["measured_um"])
    report = tmp_path / "r.html"
    assert main(["report", str(folder), "--model", str(tmp_path / "m.toml"), "--standard",
                 "iso230-3", "--out", str(report)]) == 0
    assert 'alt="ISO 230-3 deviations over time with the duty"' in report.read_text()


def test_iso230_3_says_what_a_thermal_test_lacks(tmp_path, capsys):
    """One target read over time: its drift, but no expansion (two targets needed); no
    target read twice: refused."""
    from feedaxis.case import read_case, write_case
    from feedaxis.examples import write_table2_case

    full = read_case(write_table2_case(tmp_path / "full", 6000.0, noise_um=0.05, seed=2))
    positioning = full.positioning
    duty = {name: [getattr(s, name) for s in full.duty.segments]
            for name in ("start_s", "duration_s", "feed_mm_min", "from_mm", "to_mm")}
    axis = {"name": full.axis.name, "screw": full.axis.screw}
    one = positioning.target_mm == 250.0
    folder = write_case(tmp_path / "one", axis, duty=duty, positioning={
        "target_mm": positioning.target_mm[one], "error_um": positioning.error_um[one],
        "time_s": positioning.time_s[one]})
    payload = _compare(capsys, folder, "--standard", "iso230-3")
    assert list(payload["figures"]) == ["drift_250mm_um"]
    assert set(payload["needs"]) == {"expansion_um", "expansion_um_per_m",
                                     "linear_error_change_um"}
    assert payload["needs"]["expansion_um"][0].startswith("two targets at least")
    first = np.arange(positioning.size) < 11  # the first run: each target once
    folder = write_case(tmp_path / "once", axis, duty=duty, positioning={
        "target_mm": positioning.target_mm[first], "error_um": positioning.error_um[first],
        "time_s": positioning.time_s[first]})
    assert main(["compare", str(folder), "--standard", "iso230-3"]) == 2
    assert "no target is read twice" in capsys.readouterr().err
    from dataclasses import replace

    from feedaxis.effects import Model
    from feedaxis.standards.thermal import thermal_comparison

    longer = full.with_samples("positioning", replace(positioning,
                                                      target_mm=positioning.target_mm * 5))
    block = thermal_comparison(longer, Model([], {}))  # targets over 2500 mm
    assert set(block["needs"]) == {"expansion_um", "expansion_um_per_m",
                                   "linear_error_change_um"}
    assert "at most 2000 mm" in block["needs"]["expansion_um"][0]


def test_report_shows_every_standard_with_all(tmp_path):
    folder = _write_hand_case(tmp_path / "hand")
    out = tmp_path / "all.html"
    assert main(["report", str(folder), "--standard", "all", "--out", str(out)]) == 0
    page = out.read_text()
    for standard in STANDARDS.values():
        assert f"<h3>{standard.title}</h3>" in page
    assert "No figures: ASME B5.54-2005" in page and "No figures: not a thermal case" in page


def test_compare_and_the_report_label_the_rms_of_the_model_alone(tmp_path, capsys):
    """The bundled laser file: fit gives 0.4074 µm with its artefacts (a drift) fitted
    beside the model and 0.4265 µm of the model alone on every sample; compare's RMS row
    and the report's figure table show the latter and say so."""
    from importlib.resources import files

    laser = files("feedaxis") / "data" / "laser_example"
    folder, model = tmp_path / "case", tmp_path / "m.toml"
    assert main(["import", str(laser / "X-axis.rtl"), "--axis", str(laser / "axis.toml"),
                 "--out", str(folder)]) == 0
    capsys.readouterr()
    assert main(["fit", str(folder), "--add", "lead_error", "--add", "backlash", "--out",
                 str(model), "--json"]) == 0
    fitted = json.loads(capsys.readouterr().out)
    alone = fitted["rms_model_alone_um"]
    assert fitted["rms_after_um"] == pytest.approx(0.4074, abs=5e-5)
    assert alone == pytest.approx(0.4265, abs=5e-5)
    assert main(["compare", str(folder), "--model", str(model)]) == 0
    row = [line for line in capsys.readouterr().out.splitlines() if line.startswith("RMS")]
    assert row[0].split()[:4] == ["RMS", "(the", "model", "alone)"]
    assert float(row[0].split()[-1]) == pytest.approx(alone, rel=1e-3)
    page = tmp_path / "r.html"
    assert main(["report", str(folder), "--model", str(model), "--out", str(page)]) == 0
    assert f'<td>RMS (the model alone)</td><td class="number">' \
           f'{fitted["rms_before_um"]:.4g}</td><td class="number">{alone:.4g}</td>' \
        in page.read_text()


def test_the_iso230_3_plot_draws_each_target_and_direction_over_the_duty(monkeypatch):
    """Two targets read both ways over time: four lines (- dashed), one label per target,
    the duty's feed shaded on the right axis."""
    from feedaxis.physics.thermal import DutySegment
    from feedaxis.report import plots

    monkeypatch.setattr(plots, "_png", lambda figure: figure)
    time_s = np.arange(12) * 60.0
    target_mm = np.tile([0.0, 0.0, 400.0, 400.0], 3)
    direction = np.tile([1.0, -1.0], 6)
    figure = plots.thermal_drift(time_s, target_mm, direction, time_s / 100.0,
                                 [DutySegment(0.0, 300.0, 6000.0, 0.0, 400.0)])
    drift_axes, duty_axes = figure.axes
    assert [line.get_linestyle() for line in drift_axes.lines] == ["-", "--", "-", "--"]
    assert [line.get_label() for line in drift_axes.lines if not
            line.get_label().startswith("_")] == ["0 mm", "400 mm"]
    assert duty_axes.get_ylabel() == "duty feed (m/min)" and duty_axes.collections
    plots.plt.close(figure)
