"""A compensation table is written only when it is safe to load (issue 21): the laser file
of the issue (targets every 50 mm = multiples of the 10 mm lead, 3 runs per direction)
fitted with lead_error + assembly_eccentricity + backlash leaves parameters the data cannot
determine; comp-table refuses, names them and writes nothing; --force writes a table
without them and says what it risks. A table its own verification expects to make the axis
worse is refused too, and the warnings say what happened."""
import json

import numpy as np
import pytest

from feedaxis.case import read_case
from feedaxis.cli import main
from feedaxis.comptable import CONTROLLERS, grid_mm, safe_table
from feedaxis.comptable.safety import undetermined_on
from feedaxis.effects import CATALOG, Model
from feedaxis.fit import fit
from feedaxis.importers.rtl import rtl_text
from feedaxis.physics import geometry

LEAD_MM = 10.0
TARGETS_MM = np.arange(0.0, 501.0, 50.0)   # every target a multiple of the lead
CYCLES = 3
TRUTH = {"offset_um": 2.0, "slope_um_per_mm": -0.02, "cos_um": 1.5, "sin_um": -1.0,
         "backlash_um": 4.0}
UNDETERMINED = {"lead_error.offset_um", "assembly_eccentricity.cos_um",
                "assembly_eccentricity.sin_um"}


def rtl_runs(seed=21):
    """(direction, deviation per target) per rtl run, + and - alternating: lead error,
    eccentricity and backlash from TRUTH plus 0.3 µm Gaussian noise."""
    rng = np.random.default_rng(seed)
    runs = []
    for _ in range(CYCLES):
        for direction in (1.0, -1.0):
            error_um = (geometry.lead_error_um(TARGETS_MM, TRUTH["offset_um"],
                                               TRUTH["slope_um_per_mm"])
                        + geometry.eccentricity_error_um(TARGETS_MM, LEAD_MM, TRUTH["cos_um"],
                                                         TRUTH["sin_um"])
                        + geometry.backlash_error_um(direction, TRUTH["backlash_um"])
                        + rng.normal(0.0, 0.3, TARGETS_MM.size))
            runs.append((direction, error_um))
    return runs


def cli(capsys, *argv):
    """(exit code, stdout, stderr) of ``feedaxis ARGV``."""
    code = main([str(a) for a in argv])
    printed = capsys.readouterr()
    return code, printed.out, printed.err


def comp_table(capsys, case, model, controller, out, *options):
    """(exit code, stdout, stderr) of ``feedaxis comp-table`` writing ``out``."""
    return cli(capsys, "comp-table", case, "--model", model, "--controller", controller,
               "--out", out, *options)


@pytest.fixture(scope="module")
def laser_case(tmp_path_factory):
    """The imported case and the model fitted with the three effects of the issue."""
    folder = tmp_path_factory.mktemp("rtl")
    (folder / "X.rtl").write_text(rtl_text(TARGETS_MM, rtl_runs(), {"Axis": "X"}, {}))
    (folder / "axis.toml").write_text(f'name = ""\n[screw]\nlead_mm = {LEAD_MM}\n')
    assert main(["import", str(folder / "X.rtl"), "--axis", str(folder / "axis.toml"),
                 "--out", str(folder / "case")]) == 0
    assert main(["fit", str(folder / "case"), "--add", "lead_error", "--add",
                 "assembly_eccentricity", "--add", "backlash",
                 "--out", str(folder / "m.toml")]) == 0
    return folder / "case", folder / "m.toml"


def test_fit_names_every_undetermined_parameter_in_text_and_json(laser_case, capsys):
    case, _ = laser_case
    code, out, _ = cli(capsys, "fit", case, "--add", "lead_error", "--add",
                       "assembly_eccentricity", "--add", "backlash", "--json")
    assert code == 0 and set(json.loads(out)["undetermined"]) == UNDETERMINED
    code, out, _ = cli(capsys, "fit", case, "--add", "lead_error", "--add",
                       "assembly_eccentricity", "--add", "backlash")
    lines = {line.split()[0]: line for line in out.splitlines() if line.startswith("  ")}
    for key in UNDETERMINED:   # each with why the data cannot determine it
        assert "the data" in lines[key], lines[key]
    assert "the data" not in lines["backlash.backlash_um"]
    assert "the data do not" in lines["assembly_eccentricity.sin_um"]  # not "on its bound"


@pytest.mark.parametrize("controller", ["siemens", "fanuc"])
def test_comp_table_refuses_names_the_parameters_and_writes_nothing(laser_case, tmp_path,
                                                                    capsys, controller):
    case, model = laser_case
    out = tmp_path / f"x.{controller}"
    code, printed, err = comp_table(capsys, case, model, controller, out)
    assert code == 2 and not printed and not out.exists()
    assert err.startswith(f"feedaxis: refused, nothing written to {out}")
    for key in UNDETERMINED:
        assert key in err
    assert "the targets cannot resolve it" in err and "accuracy A" in err
    code, printed, _ = comp_table(capsys, case, model, controller, out, "--json")
    refusal = json.loads(printed)
    assert code == 2 and not out.exists()
    assert set(refusal["report"]["excluded"]) == {"lead_error", "assembly_eccentricity"}
    assert refusal["report"]["figures"]["A_um"]["before_um"] > 0


@pytest.mark.parametrize("controller", ["siemens", "fanuc"])
def test_force_writes_the_determined_part_and_says_what_it_risks(laser_case, tmp_path,
                                                                 capsys, controller):
    case, model = laser_case
    out = tmp_path / f"x.{controller}"
    code, printed, _ = comp_table(capsys, case, model, controller, out, "--force", "--json")
    report = json.loads(printed)
    assert code == 0 and out.exists()
    assert report["included"] == ["backlash"]
    assert any("--force without lead_error, assembly_eccentricity" in w and "uncompensated" in w
               for w in report["warnings"])
    applied = CONTROLLERS[controller].read(out.read_text())
    # backlash alone: no ripple of the undetermined eccentricity between the targets
    for direction in (1.0, -1.0):
        table_um = applied.error_um(np.linspace(0.0, 500.0, 2001), direction)
        assert np.ptp(table_um) <= 1.0
    figures = report["figures"]
    assert figures["A_um"]["after_um"] < figures["A_um"]["before_um"]


def test_a_model_written_by_hand_is_checked_on_the_case(laser_case, tmp_path, capsys):
    case, model = laser_case
    by_hand = tmp_path / "by-hand.toml"
    by_hand.write_text(model.read_text().split("[fit]")[0])
    code, _, err = comp_table(capsys, case, by_hand, "siemens", tmp_path / "x.ini")
    assert code == 2 and not (tmp_path / "x.ini").exists()
    assert "on this case the data cannot separate it" in err
    assert "assembly_eccentricity.sin_um: on this case the data do not depend on it" in err


def test_the_case_check_finds_what_the_fit_finds(laser_case):
    case = read_case(laser_case[0])
    model = Model([CATALOG[n] for n in ("lead_error", "assembly_eccentricity", "backlash")])
    result = fit(model, case)
    assert set(undetermined_on(case, result.model)) == set(result.undetermined) == UNDETERMINED
    determined = fit(Model([CATALOG["lead_error"], CATALOG["backlash"]]), case)
    assert not determined.undetermined and not undetermined_on(case, determined.model)


def test_a_model_the_data_determine_gives_a_table(laser_case, tmp_path, capsys):
    case, _ = laser_case
    model = tmp_path / "m.toml"
    assert cli(capsys, "fit", case, "--add", "lead_error", "--add", "backlash",
               "--out", model)[0] == 0
    out = tmp_path / "x.fanuc"
    code, printed, _ = comp_table(capsys, case, model, "fanuc", out, "--json")
    report = json.loads(printed)
    assert code == 0 and out.exists() and report["included"] == ["lead_error", "backlash"]
    assert report["figures"]["A_um"]["after_um"] < 0.5 * report["figures"]["A_um"]["before_um"]
    assert not any("--force" in w for w in report["warnings"])


def test_a_table_that_makes_the_axis_worse_is_refused(laser_case, tmp_path, capsys):
    case, _ = laser_case
    wrong = tmp_path / "wrong-sign.toml"   # the lead error with the sign turned
    wrong.write_text(f"[lead_error]\noffset_um = 0.0\nslope_um_per_mm = "
                     f"{-TRUTH['slope_um_per_mm']}\n")
    out = tmp_path / "x.ini"
    code, _, err = comp_table(capsys, case, wrong, "siemens", out)
    assert code == 2 and not out.exists()
    assert "the table makes the axis worse: accuracy A rises from" in err
    code, printed, _ = comp_table(capsys, case, wrong, "siemens", out, "--force")
    assert code == 0 and out.exists()
    warnings = [line for line in printed.splitlines() if line.startswith("warning:")]
    assert any("accuracy A rises from" in w for w in warnings)
    assert not any("only falls" in w for w in warnings)
    assert any("written with --force although it makes the axis worse" in w for w in warnings)
    assert "left out" not in printed   # no thermal effect named that the model lacks


def test_the_reports_table_leaves_out_the_same_effects(laser_case):
    from feedaxis.effects import load_model
    case = read_case(laser_case[0])
    model = load_model(laser_case[1], CATALOG)
    table = safe_table(case, model, grid_mm(0.0, 500.0, LEAD_MM / 8))
    assert table.included == ("backlash",)
    assert "assembly_eccentricity.sin_um" in table.excluded["assembly_eccentricity"]
    assert "lead_error.offset_um" in table.excluded["lead_error"]
