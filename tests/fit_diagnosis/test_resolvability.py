"""One resolvability rule, from the diagnosis to the table (issue 33): a catalog wavelength
the targets cannot resolve (phases not sampled, or aliased with another wavelength) is passed
over by diagnose (text and ``skipped``), undetermined in fit, refused by comp-table (written
only with --force, the risk said) and not marked in the report. On the laser example the
package ships (11 targets about 46 mm apart, a 10 mm lead) that is assembly_eccentricity, as
docs/compensation-tables.md says; a test whose targets resolve the lead keeps it, in every
command."""
import json
import re
from pathlib import Path

import numpy as np
import pytest

import synthetic as syn
from feedaxis.analysis import analyse
from feedaxis.case import read_case
from feedaxis.cli import main
from feedaxis.diagnose import diagnose
from feedaxis.effects import CATALOG, Model, load_model
from feedaxis.examples import LASER_EXAMPLE

ROOT = Path(__file__).resolve().parents[2]
THREE = ("--add", "lead_error", "--add", "assembly_eccentricity", "--add", "backlash")
TERMS = {"assembly_eccentricity.cos_um", "assembly_eccentricity.sin_um"}


def cli(capsys, *argv):
    code = main([str(a) for a in argv])
    printed = capsys.readouterr()
    return code, printed.out, printed.err


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """The shipped laser example imported, and the model fitted with the three effects."""
    folder = tmp_path_factory.mktemp("example")
    assert main(["import", str(LASER_EXAMPLE / "X-axis.rtl"), "--axis",
                 str(LASER_EXAMPLE / "axis.toml"), "--out", str(folder / "case")]) == 0
    assert main(["fit", str(folder / "case"), *THREE, "--out", str(folder / "m.toml")]) == 0
    return folder / "case", folder / "m.toml"


def test_diagnose_passes_the_example_eccentricity_over_with_the_reason(example, capsys):
    case, _ = example
    code, out, _ = cli(capsys, "diagnose", case)
    assert code == 0
    assert re.search(r"passed over assembly_eccentricity: the 11 targets cannot tell its 10 mm "
                     r"wavelength from [\d.]+ mm", out)
    code, out, _ = cli(capsys, "diagnose", case, "--json")
    diagnosis = json.loads(out)
    assert "cannot tell its 10 mm wavelength" in diagnosis["skipped"]["assembly_eccentricity"]
    assert "assembly_eccentricity" not in [c["effect"] for c in diagnosis["candidates"]]


def test_fit_calls_the_example_eccentricity_undetermined(example, capsys):
    case, model = example
    code, out, _ = cli(capsys, "fit", case, *THREE, "--json")
    assert code == 0 and set(json.loads(out)["undetermined"]) == TERMS
    fitted = model.read_text()
    assert all(f'"{term}" = "the targets cannot resolve it' in fitted for term in TERMS)


@pytest.mark.parametrize("controller", ["siemens", "fanuc"])
def test_comp_table_refuses_the_example_model_and_force_says_the_risk(example, tmp_path,
                                                                      capsys, controller):
    case, model = example
    out = tmp_path / f"x.{controller}"
    code, printed, err = cli(capsys, "comp-table", case, "--model", model, "--controller",
                             controller, "--out", out)
    assert code == 2 and not out.exists() and not printed
    assert "assembly_eccentricity: the targets cannot resolve it" in err
    code, printed, _ = cli(capsys, "comp-table", case, "--model", model, "--controller",
                           controller, "--out", out, "--force", "--json")
    report = json.loads(printed)
    assert code == 0 and out.exists()
    assert "assembly_eccentricity" not in report["included"]
    assert any("assembly_eccentricity" in w and "uncompensated" in w for w in report["warnings"])


def test_the_report_marks_no_unresolved_wavelength(example):
    case, model = example
    details = analyse(read_case(case), load_model(model, CATALOG)).details
    assert "assembly_eccentricity" not in details.marks
    assert "cannot tell" in details.unresolved["assembly_eccentricity"]


def test_the_docs_say_what_the_example_does():
    page = (ROOT / "docs" / "compensation-tables.md").read_text(encoding="utf-8")
    assert "it passes over `assembly_eccentricity`" in page
    assert "a\ntable from a model holding it anyway is refused" in page or \
        "a table from a model holding it anyway is refused" in " ".join(page.split())


@pytest.fixture(scope="module")
def resolvable(tmp_path_factory):
    """81 targets 4.9 mm apart over 392 mm (staggered by up to ±0.5 mm), 10 mm lead,
    3 bidirectional cycles: lead error, a 1.5 µm eccentricity, B = 4 µm, 0.3 µm noise."""
    return syn.staggered_case(tmp_path_factory.mktemp("resolvable") / "case", 12, (1.2, -0.9),
                              0.3)


def test_a_resolvable_eccentricity_is_named_determined_and_tabled(resolvable, tmp_path, capsys):
    code, out, _ = cli(capsys, "diagnose", resolvable, "--json")
    diagnosis = json.loads(out)
    assert "assembly_eccentricity" not in diagnosis["skipped"]
    assert "assembly_eccentricity" in [c["effect"] for c in diagnosis["candidates"]]
    model = tmp_path / "m.toml"
    code, out, _ = cli(capsys, "fit", resolvable, *THREE, "--json", "--out", model)
    assert code == 0 and not json.loads(out)["undetermined"]
    code, out, _ = cli(capsys, "comp-table", resolvable, "--model", model, "--controller",
                       "siemens", "--out", tmp_path / "x.ini", "--json")
    assert code == 0 and "assembly_eccentricity" in json.loads(out)["included"]


@pytest.mark.parametrize("jitter_mm", [0.0, 1.0])
def test_a_zigzag_on_the_aliases_of_the_lead_names_no_eccentricity(jitter_mm):
    """A repeat test (5 runs each way) at 21 targets every 15 mm (± ``jitter_mm``) on a
    10 mm lead, with a ±4.5 µm zig-zag between neighbouring targets: at the targets
    cos(2πx/10 mm) is that zig-zag, so an eccentricity would fit it; the rule passes it
    over (phases not sampled, or aliased with about 30 mm) and the zig-zag is reported as a
    periodic error at twice the spacing."""
    rng = np.random.default_rng(7)
    targets = np.arange(21) * 15.0 + np.round(rng.uniform(-jitter_mm, jitter_mm, 21), 3)
    zigzag_um = 4.5 * (-1.0) ** np.arange(21)
    index = np.concatenate([np.r_[0:21, 20:-1:-1]] * 5)
    direction = np.tile(np.repeat([1.0, -1.0], 21), 5)
    error_um = (0.01 * targets[index] + zigzag_um[index] + direction
                + rng.normal(0.0, 0.5, index.size))
    case = syn.in_memory_case(syn.ISO_AXIS, target_mm=targets[index], error_um=error_um,
                              direction=direction, run=np.repeat(np.arange(1.0, 6.0), 42))
    found = diagnose(case, Model([CATALOG["lead_error"]]))
    assert "assembly_eccentricity" not in [c.effect for c in found.candidates]
    assert "10 mm wavelength" in found.skipped["assembly_eccentricity"]
    assert found.unexplained[0].kind == "periodic"
    assert found.unexplained[0].wavelength_mm == pytest.approx(30.0, rel=0.05)
