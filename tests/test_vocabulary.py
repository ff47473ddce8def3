"""One vocabulary (issue 21): µm in every text a person reads (JSON keys keep ``_um``),
p-values written alike everywhere, the noise a diagnosis prints and the test it decided
by naming the same noise model, and help texts that describe the method used."""
import re

import numpy as np
import pytest

import synthetic as syn
from feedaxis import text
from feedaxis.case import read_case
from feedaxis.cli import COMMANDS, SCENARIOS, build_parser, main
from feedaxis.diagnose import diagnose
from feedaxis.effects import CATALOG, Model
from feedaxis.stats import noise
from feedaxis.stats.judge import Test as FTest
from feedaxis.stats.wording import p_text

MICRONS_AS_UM = re.compile(r"(?<![\w_])um(?![\w_])")
P_VALUE = re.compile(r"\bp\b(?! = \S| < 1e-300)")   # a "p" not followed by "= x" or "< 1e-300"
NOISE_MODELS = [noise.PureError, noise.ResidualMeanSquare, noise.Coloured]


def test_p_values_are_written_one_way():
    assert p_text(2.1e-5) == "p = 2.1e-05"
    assert p_text(0.0) == p_text(1e-320) == "p < 1e-300"
    assert p_text(0.5) == "p = 0.5"
    assert FTest(2.78e3, (2, 2497), 0.0, "t").describe() == "F(2, 2497) = 2.78e+03, p < 1e-300"
    assert FTest(4.54, (2, 40), 0.013, "t").describe().endswith("p = 0.013")


def test_every_noise_model_names_itself_in_its_test_and_its_noise():
    """Each noise model's label is in its test's name and in the source of its noise
    estimate, and no other model's label is: the two lines cannot contradict each other."""
    assert {cls.__name__ for cls in NOISE_MODELS} == {
        name for name, value in vars(noise).items()
        if isinstance(value, type) and hasattr(value, "extra_ss_test")}
    for cls in NOISE_MODELS:
        others = [other.label for other in NOISE_MODELS if other is not cls]
        assert cls.label in cls.name and not any(o in cls.name for o in others), cls
    residual = np.random.default_rng(1).normal(0.0, 1.0, 200)
    coloured_source = noise.Coloured().estimate_um(residual)[1]
    assert noise.Coloured.label in coloured_source


@pytest.mark.parametrize("trial", ["iso_trial", "scan_trial"])
def test_a_diagnosis_names_one_noise_model(trial):
    """A case with repeats and a dense scan without: the noise line and the test line of
    the diagnosis (text and JSON) carry the same noise model's label, and only it."""
    case, _ = getattr(syn, trial)(np.random.default_rng(4))
    diagnosis = diagnose(case, Model([CATALOG["lead_error"]]))
    expected = noise.PureError if trial == "iso_trial" else noise.ResidualMeanSquare
    lines = text.diagnosis_lines(diagnosis).splitlines()
    noise_line = next(line for line in lines if line.startswith("residual RMS"))
    test_line = next(line for line in lines if line.strip().startswith("test:"))
    for line in (noise_line, test_line, diagnosis.to_json()["noise_source"],
                 diagnosis.to_json()["test"]):
        assert expected.label in line
        assert not any(other.label in line for other in NOISE_MODELS if other is not expected)


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
    found += [(f"simulate {name}", scenarios[name].format_help()) for name, *_ in SCENARIOS]
    return found


def test_help_texts_describe_the_method_used():
    helps = dict(help_texts())
    assert len(helps) == len(COMMANDS) + len(SCENARIOS)
    for name, help_text in helps.items():
        assert not MICRONS_AS_UM.search(help_text), name
    diagnose_help = " ".join(helps["diagnose"].split())
    assert "BIC" not in diagnose_help and "rank" not in diagnose_help
    for words in ("F test", "pure error of repeated samples", "residual mean square",
                  "effective sample count", "family-wise error rate of 0.001", "Bonferroni",
                  "adequate, missing_effect or unexplained"):
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
