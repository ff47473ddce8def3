"""feedaxis uncertainty: the Monte Carlo method against JCGM 101's worked examples and the
GUM law of propagation, the 20 °C correction against the expansion it removes, seeded
reruns, the adaptive stop, the linearised fit against refits, bad budgets."""
import json
import math

import numpy as np
import pytest
from scipy import integrate, optimize, stats

import synthetic as syn
from feedaxis.case import read_case, write_case
from feedaxis.cli import main
from feedaxis.comptable import from_measurement
from feedaxis.effects import CATALOG
from feedaxis.iso230 import iso230_figures
from feedaxis.physics import geometry
from feedaxis.uncertainty import engine
from feedaxis.uncertainty.budget import Budget, CONTRIBUTIONS, read_budget
from feedaxis.uncertainty.correction import corrected_case
from feedaxis.uncertainty.distributions import Distribution
from feedaxis.uncertainty.evaluation import evaluate
from feedaxis.uncertainty.positioning import PositioningMeasurement

ROOT3 = math.sqrt(3.0)
TRIALS = 10 ** 6
ALPHA_PER_K = 11.7e-6
FIXED_END_MM = -141.0


def only(**sizes):
    """A budget of the named contributions (normal, standard uncertainty given), the
    others 0."""
    distributions = {name: Distribution("normal", sizes.get(name, 0.0))
                     for name in CONTRIBUTIONS}
    return Budget(distributions, {name: "test" for name in CONTRIBUTIONS})


def iso_case(folder, noise_um=0.3, backlash_um=2.0, seed=1, shift_um=None,
             slope_um_per_mm=0.012):
    """5 runs each way at 11 targets over 500 mm: lead error, backlash, noise (identical
    runs when ``noise_um`` is 0), plus ``shift_um(target_mm)`` when given."""
    target_mm, direction, run = syn.iso_layout(n_targets=11, n_runs=5)
    error_um = (geometry.lead_error_um(target_mm, 1.5, slope_um_per_mm)
                + geometry.backlash_error_um(direction, backlash_um)
                + np.random.default_rng(seed).normal(0.0, noise_um, target_mm.size))
    if shift_um is not None:
        error_um = error_um + shift_um(target_mm)
    return read_case(write_case(folder, syn.ISO_AXIS, positioning={
        "target_mm": target_mm, "error_um": error_um, "direction": direction, "run": run}))


# --- the Monte Carlo method: JCGM 101 §9.2, and the GUM law where the model is linear ---

def additive(distributions):
    """JCGM 101 §9.2: Y = X1 + X2 + X3 + X4, the inputs independent."""
    names = [f"X{i}" for i in range(1, 5)]

    def sample(streams, trials, active, skip):
        return {"y": sum(d.sample(streams[n], trials) for n, d in zip(names, distributions)
                         if n in active)}
    values = engine.run(sample, names, TRIALS, 2008, 250_000)["y"]
    kurtosis = stats.kurtosis(values, fisher=False)
    return engine.summarise(values), 0.005 + 4 * values.std() * math.sqrt(
        (kurtosis - 1) / (4 * TRIALS))


def quantile_tolerance(density):
    """Half a unit in the published last decimal plus 4 Monte Carlo standard errors of a
    97.5 % quantile, sqrt(p(1 - p)/M) / g(y) (as the R package propagate gauges it)."""
    return 0.005 + 4 * math.sqrt(0.025 * 0.975 / TRIALS) / density


def test_jcgm101_9_2_2_normal_inputs_give_the_published_interval():
    """§9.2.2, X_i ~ N(0, 1): JCGM 101:2008 Table 2 gives u(y) = 2.00 and the 95 % interval
    [-3.92, 3.92] (the values Sandia's suncal tests against, test/test_examples.py)."""
    summary, u_tolerance = additive([Distribution("normal", 1.0)] * 4)
    tolerance = quantile_tolerance(stats.norm.pdf(1.96) / 2.0)
    assert summary.standard_uncertainty == pytest.approx(2.00, abs=u_tolerance)
    assert summary.symmetric.ravel() == pytest.approx([-3.92, 3.92], abs=tolerance)
    assert summary.shortest.ravel() == pytest.approx([-3.92, 3.92], abs=tolerance)


def test_jcgm101_9_2_3_rectangular_inputs_give_the_published_interval():
    """§9.2.3, X_i rectangular with expectation 0 and standard deviation 1 (half-width √3):
    Table 3 gives u(y) = 2.00 and [-3.88, 3.88], narrower than the GUM's ±3.92."""
    summary, u_tolerance = additive([Distribution("rectangular", ROOT3)] * 4)
    tolerance = quantile_tolerance(stats.norm.pdf(1.94) / 2.0)
    assert summary.standard_uncertainty == pytest.approx(2.00, abs=u_tolerance)
    assert summary.symmetric.ravel() == pytest.approx([-3.88, 3.88], abs=tolerance)


def test_jcgm101_9_2_4_one_dominant_rectangular_input_gives_the_exact_interval():
    """§9.2.4, X4's standard deviation ten times the others': u(y) = √103 = 10.15 and the
    GUM interval ±19.9 is far too wide. The interval is checked against the exact 97.5 %
    quantile of the convolution (a rectangular of half-width 10√3 over the Irwin-Hall sum of
    three of half-width √3), computed here by quadrature."""
    summary, u_tolerance = additive([Distribution("rectangular", ROOT3)] * 3
                                    + [Distribution("rectangular", 10 * ROOT3)])
    half = 10 * ROOT3

    def cdf(y):
        three = lambda s: stats.irwinhall(3).cdf((s + 3 * ROOT3) / (2 * ROOT3))  # noqa: E731
        return integrate.quad(lambda u: three(y - u), -half, half, limit=200)[0] / (2 * half)
    exact = optimize.brentq(lambda y: cdf(y) - 0.975, 15.0, 19.0, xtol=1e-6)
    density = 1 / (2 * half)
    assert summary.standard_uncertainty == pytest.approx(math.sqrt(103), abs=u_tolerance)
    assert summary.symmetric.ravel() == pytest.approx([-exact, exact],
                                                      abs=quantile_tolerance(density))
    assert exact < 1.96 * math.sqrt(103) - 2.5


def test_linear_case_monte_carlo_equals_the_gum_law_of_propagation(tmp_path):
    """Identical runs with an error rising along the travel: E↑ moves linearly with the
    laser's scale error ε and the set-up error a (normal), so the GUM law of propagation
    gives u(E↑) = sqrt((span·u_ε)² + u_a²) and the interval E↑ ± 1.96 u; the Monte Carlo
    agrees within its numerical tolerance (JCGM 101 §8.1: half a unit in the second
    significant digit of u). B̄ does not move at all."""
    case = iso_case(tmp_path / "c", noise_um=0.0)
    result = evaluate(case, budget=only(device_calibration=2.0, setup=0.3), seed=3)
    span_mm = float(np.ptp(case.positioning.target_mm))
    gum_u = math.hypot(span_mm * 1e-3 * 2.0, 0.3)
    figure = result.figures["E_up_um"]
    delta = 0.5 * 10 ** (math.floor(math.log10(gum_u)) - 1)
    assert figure["standard_uncertainty_um"] == pytest.approx(gum_u, abs=delta)
    value = figure["value_um"]
    assert figure["coverage_interval_um"] == pytest.approx(
        [value - 1.96 * gum_u, value + 1.96 * gum_u], abs=delta)
    assert result.figures["B_mean_um"]["standard_uncertainty_um"] < 1e-9


def test_linearised_fit_equals_the_fit_own_uncertainty_and_refits(tmp_path):
    """On a dense single scan the repeatability comes from the fit's residual: with no
    budget the Monte Carlo standard uncertainty of each fitted parameter is the fit's own
    (the GUM's, covariance from the Jacobian) times sqrt(ν/(ν - 2)) of the t-distribution,
    and refitting trials gives the linearised parameters."""
    case = read_case(syn.micro_case(tmp_path / "m", ("lead_error", "assembly_eccentricity"),
                                    seed=5))
    model = CATALOG["lead_error"] + CATALOG["assembly_eccentricity"]
    result = evaluate(case, model, budget=only(), trials=10_000, seed=1)
    assert result.parameter_method["method"] == "linearised fit"
    assert result.parameter_method["largest_refit_difference_in_u"] < 1e-4
    for key, entry in result.parameters.items():
        assert entry["standard_uncertainty"] == pytest.approx(
            entry["fit_standard_uncertainty"], rel=0.03), key


def test_measured_means_table_of_a_trial_is_that_trials_table(tmp_path):
    """The table of measured means moves with the trials exactly as comp-table builds it
    from the trial's deviations."""
    case = iso_case(tmp_path / "c")
    measurement = PositioningMeasurement(case, only())
    trials = case.positioning.error_um + np.random.default_rng(0).normal(0, 1, (3, 110))
    got = measurement.table.of(trials, None)["table_um"]
    for values, table in zip(trials, got):
        samples = case.positioning.__class__(
            case.positioning.target_mm, values, case.positioning.direction,
            case.positioning.run, has_direction=True)
        case_t = case.__class__(case.folder, case.axis, {"positioning": samples})
        expected = from_measurement(case_t, measurement.table.position_mm)
        assert table == pytest.approx(np.stack((expected.forward_um, expected.reverse_um), -1),
                                      abs=1e-12)


def test_figures_of_many_trials_are_each_trials_figures(tmp_path):
    """The trials axis of iso230_figures: the figures of a (trials, samples) array equal the
    figures of each row computed alone, bidirectional and for one run per target."""
    case = iso_case(tmp_path / "c")
    target_mm, direction = case.positioning.target_mm, case.positioning.direction
    trials = case.positioning.error_um + np.random.default_rng(3).normal(0, 0.5, (4, 110))
    for targets, directions, values in ((target_mm, direction, trials),
                                        (target_mm[:11], direction[:11], trials[:, :11])):
        together = iso230_figures(targets, values, directions)
        for row, single in enumerate(values):
            alone = iso230_figures(targets, single, directions)
            assert together.keys() == alone.keys()
            for key, value in alone.items():
                got = together[key] if isinstance(together[key], int) else together[key][row]
                assert got == pytest.approx(value, abs=1e-12), key


def test_report_and_comp_table_take_the_correction(tmp_path, capsys):
    """report and comp-table run on the corrected deviations: comp-table's expected figures
    before the table are those of the case corrected to 20 °C."""
    case = iso_case(tmp_path / "c")
    model = str(tmp_path / "m.toml")
    assert main(["fit", str(case.folder), "--add", "lead_error", "--add", "backlash",
                 "--out", model, "--correct-to-20C", "21.5"]) == 0
    assert main(["report", str(case.folder), "--model", model, "--out",
                 str(tmp_path / "r.html"), "--correct-to-20C", "21.5"]) == 0
    capsys.readouterr()
    assert main(["comp-table", str(case.folder), "--model", model, "--controller", "linuxcnc",
                 "--out", str(tmp_path / "t.comp"), "--correct-to-20C", "21.5", "--json"]) == 0
    before = json.loads(capsys.readouterr().out)["figures"]
    corrected = corrected_case(case, 21.5).positioning
    expected = iso230_figures(corrected.target_mm, corrected.error_um, corrected.direction)
    for key, entry in before.items():
        assert entry["before_um"] == pytest.approx(expected[key], abs=1e-9), key
    assert (tmp_path / "r.html").stat().st_size > 0


# --- the 20 °C correction ------------------------------------------------------------------

def test_uniform_temperature_gives_the_known_change_of_every_figure(tmp_path):
    """A case measured at a uniform 25 °C is the 20 °C case plus α·5 K·(X - X_ref): the
    correction gives back every figure of the 20 °C case, E↑ having fallen by α·5 K·span;
    its uncertainty grows by the temperature's and the coefficient's terms,
    span·sqrt((α·u_T)² + (ΔT·u_α)²), and the figures the expansion cannot move (B, B̄, R)
    get none."""
    expansion = lambda x: ALPHA_PER_K * 5.0 * (x - FIXED_END_MM) * 1e3  # noqa: E731
    at_20 = iso_case(tmp_path / "a", noise_um=0.0, slope_um_per_mm=0.1)
    at_25 = iso_case(tmp_path / "b", noise_um=0.0, shift_um=expansion, slope_um_per_mm=0.1)
    corrected = corrected_case(at_25, 25.0)
    expected = iso230_figures(at_20.positioning.target_mm, at_20.positioning.error_um,
                              at_20.positioning.direction)
    got = iso230_figures(corrected.positioning.target_mm, corrected.positioning.error_um,
                         corrected.positioning.direction)
    before = iso230_figures(at_25.positioning.target_mm, at_25.positioning.error_um,
                            at_25.positioning.direction)
    span_mm = float(np.ptp(at_25.positioning.target_mm))
    for key, value in expected.items():
        assert got[key] == pytest.approx(value, abs=1e-9), key
    assert before["E_up_um"] - got["E_up_um"] == pytest.approx(ALPHA_PER_K * 5 * span_mm * 1e3,
                                                               abs=1e-9)
    budget = only(device_calibration=1.0, machine_temperature=0.2, expansion_coefficient=1e-6)
    plain = evaluate(at_25, budget=budget, seed=2, trials=50_000)
    with_correction = evaluate(at_25, budget=budget, seed=2, temperature=25.0, trials=50_000)
    added = span_mm * 1e3 * math.hypot(ALPHA_PER_K * 0.2, 5.0 * 1e-6)
    u = {key: (plain.figures[key]["standard_uncertainty_um"],
               with_correction.figures[key]["standard_uncertainty_um"]) for key in expected
         if key.endswith("_um")}
    assert math.sqrt(u["E_up_um"][1] ** 2 - u["E_up_um"][0] ** 2) == pytest.approx(added,
                                                                                  rel=0.02)
    assert with_correction.figures["E_up_um"]["value_um"] == pytest.approx(got["E_up_um"])
    for key in ("B_um", "B_mean_um", "R_um"):
        assert u[key][1] < 1e-9, key


def test_compare_corrects_to_20C_and_refuses_what_it_cannot(tmp_path, capsys):
    expansion = lambda x: ALPHA_PER_K * 3.0 * (x - FIXED_END_MM) * 1e3  # noqa: E731
    at_20 = iso_case(tmp_path / "a", noise_um=0.0)
    at_23 = iso_case(tmp_path / "b", noise_um=0.0, shift_um=expansion)
    figures = {}
    for name, case, options in (("20", at_20, []), ("23", at_23, ["--correct-to-20C", "23"])):
        assert main(["compare", str(case.folder), "--json", *options]) == 0
        figures[name] = json.loads(capsys.readouterr().out)["figures"]
    for key, entry in figures["20"].items():
        assert figures["23"][key]["measured_um"] == pytest.approx(entry["measured_um"],
                                                                  abs=1e-9), key
    assert main(["compare", str(at_23.folder), "--json", "--correct-to-20C", "ambient"]) == 2
    error = json.loads(capsys.readouterr().out)
    assert error["column"] == "ambient_C" and error["file"].endswith("positioning.csv")
    assert main(["compare", str(at_23.folder), "--correct-to-20C", "warm"]) == 2
    assert "--correct-to-20C warm" in capsys.readouterr().err


# --- seeds, the adaptive stop -----------------------------------------------------------

def test_the_same_seed_gives_the_same_intervals(tmp_path):
    case = iso_case(tmp_path / "c")
    first, again, other = (evaluate(case, trials=5_000, seed=seed).to_json()
                           for seed in (11, 11, 12))
    assert first["figures"] == again["figures"]
    assert first["figures"]["A_um"] != other["figures"]["A_um"]


def test_adaptive_stop_is_reached_within_the_asked_tolerance(tmp_path):
    """JCGM 101 §7.9: the run stops once twice the standard deviation of every block result
    is within 0.02 µm; two such runs with different seeds then agree within that
    tolerance's reach (twice it, each being a mean within the tolerance)."""
    case = iso_case(tmp_path / "c")
    runs = [evaluate(case, tolerance_um=0.02, seed=seed) for seed in (1, 2)]
    for result in runs:
        assert result.adaptive.stabilised and result.adaptive.reached <= 0.02
        assert result.trials == result.adaptive.blocks * engine.BLOCK_TRIALS
    for key, first in runs[0].figures.items():
        second = runs[1].figures[key]
        for name in ("mean_um", "standard_uncertainty_um"):
            assert abs(first[name] - second[name]) <= 2 * 0.02, (key, name)
        assert first["coverage_interval_um"] == pytest.approx(second["coverage_interval_um"],
                                                              abs=2 * 0.02), key


# --- the command: strict JSON, the page, bad budgets --------------------------------------

def test_uncertainty_command_json_keys_follow_compare(tmp_path, capsys):
    case = iso_case(tmp_path / "c")
    page = tmp_path / "u.html"
    assert main(["uncertainty", str(case.folder), "--trials", "2000", "--seed", "4",
                 "--json", "--html", str(page)]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert main(["compare", str(case.folder), "--json"]) == 0
    compared = json.loads(capsys.readouterr().out)["figures"]
    assert list(payload["figures"]) == list(compared)
    for key, entry in payload["figures"].items():
        assert entry["value_um"] == pytest.approx(compared[key]["measured_um"])
        low, high = entry["coverage_interval_um"]
        assert low <= entry["mean_um"] <= high and entry["standard_uncertainty_um"] > 0
    assert payload["seed"] == 4 and payload["trials"] == 2000
    assert page.read_text().count("<img") == 2


BAD_BUDGETS = {
    "unknown contribution": ("[laser_wobble]\nhalf_width_um = 1\n", 1, "laser_wobble",
                             "unknown contribution"),
    "negative half-width": ("[setup]\ndistribution = \"rectangular\"\nhalf_width_um = -0.1\n",
                            3, "setup.half_width_um", "must be a finite number >= 0"),
    "unknown distribution": ("# lab budget\n[eve]\ndistribution = \"lognormal\"\n"
                             "half_width_um = 0.1\n", 3, "eve.distribution",
                             "unknown distribution"),
    "repeatability in the budget": ("[repeatability]\nhalf_width_um = 1\n", 1, "repeatability",
                                    "comes from the case's own runs"),
    "wrong unit": ("[device_calibration]\nhalf_width_um = 1\n", 2,
                   "device_calibration.half_width_um", "unknown key"),
}


@pytest.mark.parametrize("name", BAD_BUDGETS)
def test_bad_budget_is_refused_with_file_line_and_key(tmp_path, capsys, name):
    text, line, key, words = BAD_BUDGETS[name]
    budget = tmp_path / "budget.toml"
    budget.write_text(text)
    case = iso_case(tmp_path / "c")
    page = tmp_path / "u.html"
    assert main(["uncertainty", str(case.folder), "--budget", str(budget), "--json",
                 "--html", str(page)]) == 2
    error = json.loads(capsys.readouterr().out)
    assert (error["file"], error["row"], error["column"]) == (str(budget), line, key)
    assert words in error["error"] and not page.exists()


def test_a_certificate_budget_is_read():
    """A normal contribution from a certificate's U and k; a file's sources are kept."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "b.toml"
        path.write_text('[device_calibration]\ndistribution = "normal"\nexpanded_ppm = 0.6\n'
                        'coverage_factor = 2\nsource = "certificate 42"\n')
        budget = read_budget(path)
    assert budget.distributions["device_calibration"] == Distribution("normal", 0.3)
    assert budget.sources["device_calibration"].endswith("certificate 42")
    assert budget.distributions["eve"] == CONTRIBUTIONS["eve"].default
