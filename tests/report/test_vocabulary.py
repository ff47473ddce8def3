"""One vocabulary (issue 21): µm in every text a person reads (JSON keys keep ``_um``),
p-values written alike everywhere, the noise a diagnosis prints and the test it decided
by naming the same noise model, and help texts that describe the method used."""
import re

import numpy as np
import pytest

import synthetic as syn
from feedaxis import text
from feedaxis.case import read_case
from feedaxis.cli import COMMANDS, build_parser, main
from feedaxis.kinds import scenarios as registered_scenarios
from feedaxis.diagnose import diagnose
from feedaxis.effects import CATALOG, Model
from feedaxis.measurement import measurement_of
from feedaxis.physics import geometry
from feedaxis.stats import noise
from feedaxis.stats.judge import Test as FTest
from feedaxis.stats.wording import p_text

MICRONS_AS_UM = re.compile(r"(?<![\w_-])um(?![\w_])")   # not in --tolerance-um
P_VALUE = re.compile(r"\bp\b(?! = \S| < 1e-300)")   # a "p" not followed by "= x" or "< 1e-300"


def test_p_values_are_written_one_way():
    assert p_text(2.1e-5) == "p = 2.1e-05"
    assert p_text(0.0) == p_text(1e-320) == "p < 1e-300"
    assert p_text(0.5) == "p = 0.5"
    assert FTest(2.78e3, (2, 2497), 0.0, "t").describe() == "F(2, 2497) = 2.78e+03, p < 1e-300"
    assert FTest(4.54, (2, 40), 0.013, "t").describe().endswith("p = 0.013")


LABELS = ("repeated samples", "+ and - readings at each target", "no replicates",
          "serially correlated noise")


def assert_one_noise_model(label, *lines):
    """Every line carries ``label`` and no other noise model's label."""
    assert label in LABELS
    for line in lines:
        assert label in line, (label, line)
        assert not any(other in line for other in LABELS if other != label), (label, line)


def one_pass_each_way(rng):
    """One + and one - pass over 21 targets: replicates as pairs about a constant reversal."""
    target_mm, direction, run = syn.iso_layout(n_runs=1)
    error_um = (geometry.lead_error_um(target_mm, 1.5, -0.012)
                + geometry.backlash_error_um(direction, 2.0)
                + rng.normal(0.0, syn.ISO_NOISE_UM, target_mm.size))
    return syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=error_um,
                              direction=direction, run=run), None


def correlated_scan(rng):
    """A dense scan whose noise is an AR(1) process along the pass (φ = 0.9)."""
    target_mm = np.arange(0.0, 501.0, 1.0)
    noise_um = np.zeros(target_mm.size)
    for index in range(1, target_mm.size):
        noise_um[index] = 0.9 * noise_um[index - 1] + rng.normal(0.0, syn.ISO_NOISE_UM)
    error_um = geometry.lead_error_um(target_mm, 1.5, -0.012) + noise_um
    return syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=error_um), None


@pytest.mark.parametrize("layout, label", [
    (syn.iso_trial, "repeated samples"), (one_pass_each_way, "+ and - readings at each target"),
    (syn.scan_trial, "no replicates"), (correlated_scan, "no replicates")])
def test_a_diagnosis_names_one_noise_model(layout, label):
    """Repeated runs, one pass each way, a white and a serially correlated scan: the noise
    line and the test line of the diagnosis (text and JSON) carry the same noise model's
    label, and no other's."""
    case, _ = layout(np.random.default_rng(4))
    diagnosis = diagnose(case, Model([CATALOG["lead_error"]]))
    assert measurement_of(case, "positioning").noise.label == label
    lines = text.diagnosis_lines(diagnosis).splitlines()
    noise_line = next(line for line in lines if line.startswith("residual RMS"))
    test_line = next(line for line in lines if line.strip().startswith("test:"))
    payload = diagnosis.to_json()
    assert_one_noise_model(label, noise_line, test_line, payload["noise_source"],
                           payload["test"])
    if layout is correlated_scan:
        assert "serially correlated" in noise_line


def test_a_tracking_trace_names_its_noise_model():
    residual = np.random.default_rng(1).normal(0.0, 1.0, 200)
    assert_one_noise_model(noise.Coloured.label, noise.Coloured.name,
                           noise.Coloured().estimate_um(residual)[1])


@pytest.fixture(scope="module")
def fitted_case(tmp_path_factory):
    """An ISO case with backlash, a model fitted to it, and a thermal case and model."""
    from feedaxis.examples import write_table2_case

    folder = tmp_path_factory.mktemp("v")
    case = syn.iso_case(folder / "case", seed=32, backlash_um=-4.0)
    assert main(["fit", str(case), "--add", "lead_error", "--add", "backlash",
                 "--out", str(folder / "m.toml")]) == 0
    thermal = write_table2_case(folder / "thermal", 9000.0, stroke_mm=(0.0, 200.0))
    assert main(["fit", str(thermal), "--add", "lead_error", "--add", "thermal_screw",
                 "--out", str(folder / "t.toml")]) == 0
    return folder


def test_human_output_writes_micrometres_as_um_nowhere(fitted_case, capsys):
    """The text of every command that prints results: µm, never um; p-values one way."""
    folder = fitted_case
    case, model = str(folder / "case"), str(folder / "m.toml")
    commands = [
        ["fit", case, "--add", "lead_error", "--add", "backlash"],
        ["diagnose", case],
        ["diagnose", case, "--model", model],
        ["compare", case, "--model", model],
        ["effects"],
        ["comp-table", case, "--model", model, "--controller", "linuxcnc",
         "--out", str(folder / "x.comp")],
        ["compensate", str(folder / "thermal"), "--model", str(folder / "t.toml")],
    ]
    capsys.readouterr()
    for argv in commands:
        assert main(argv) == 0, argv
        printed = capsys.readouterr().out
        assert "µm" in printed, argv
        assert not MICRONS_AS_UM.search(printed), (argv, MICRONS_AS_UM.search(printed))
        assert not P_VALUE.search(printed.replace("P-V", "")), argv
    assert main(["effects", "--json"]) == 0   # JSON keeps its units and keys
    assert '"unit": "um"' in capsys.readouterr().out


def help_texts():
    """(command, its --help text) of every command and scenario."""
    parser = build_parser()
    choices = parser._subparsers._group_actions[0].choices
    found = [(name, choices[name].format_help()) for name, *_ in COMMANDS]
    scenarios = choices["simulate"]._subparsers._group_actions[0].choices
    found += [(f"simulate {name}", scenarios[name].format_help())
              for name in registered_scenarios()]
    return found


def test_help_texts_describe_the_method_used():
    helps = dict(help_texts())
    assert len(helps) == len(COMMANDS) + len(registered_scenarios())
    for name, help_text in helps.items():
        assert not MICRONS_AS_UM.search(help_text), name
    diagnose_help = " ".join(helps["diagnose"].split())
    assert "BIC" not in diagnose_help and "rank" not in diagnose_help
    for words in ("F test", "pure error of repeated samples", "residual mean square",
                  "serially correlated", "effective sample count",
                  "family-wise error rate of 0.001", "Bonferroni",
                  "adequate, missing_effect, unexplained, or undetermined"):
        assert words in diagnose_help
    assert "variable projection" in " ".join(helps["fit"].split())


def test_the_report_writes_p_values_and_micrometres_alike(tmp_path):
    from feedaxis.analysis import analyse
    from feedaxis.report import write_report

    case = read_case(syn.iso_case(tmp_path / "case", seed=32, backlash_um=-4.0))
    page = write_report(analyse(case, Model()), tmp_path / "r.html").read_text(encoding="utf-8")
    cells = re.findall(r"<td[^>]*>(p[^<]*)</td>", page)
    assert cells and all(re.fullmatch(r"p = \S+|p < 1e-300", cell) for cell in cells)
    assert not MICRONS_AS_UM.search(re.sub(r"<img[^>]*>", "", page))
