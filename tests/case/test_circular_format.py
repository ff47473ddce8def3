"""Circular tests (ISO 230-4): the case format 1.2 reader and writer, and the figures."""
import json
import math

import numpy as np
import pytest
import tomli_w

from feedaxis.case import CaseError, read_case, write_case
from feedaxis.iso230_4 import circular_figures, minimum_zone_figures, minimum_zone_um

AXIS = {"name": "VMC XY ballbar", "circular": {"axes": ["X", "Y"], "radius_mm": 100.0,
                                               "feed_mm_min": 1000.0,
                                               "center_mm": [300.0, 200.0]},
        "axes": {"X": {"screw": {"lead_mm": 10.0}},
                 "Y": {"screw": {"lead_mm": 5.0},
                       "motor": {"step_angle_deg": 1.8, "error_period_steps": 4}}}}
ANGLES = np.arange(8) * 45.0


def circle_columns():
    angle = np.concatenate((ANGLES, (360 - ANGLES) % 360))
    return {"angle_deg": angle, "deviation_um": np.cos(np.radians(angle)),
            "direction": np.repeat([1.0, -1.0], 8)}


def test_round_trip(tmp_path):
    write_case(tmp_path / "c", AXIS, circular=circle_columns())
    case = read_case(tmp_path / "c")
    assert case.axis.circular.axes == ("X", "Y") and case.axis.circular.radius_mm == 100.0
    assert case.axis.circular.center_mm == (300.0, 200.0)
    assert case.axis.axes["Y"].motor["error_period_steps"] == 4
    assert case.axis.axes["X"].lead_mm == 10.0 and case.circular.bidirectional
    np.testing.assert_array_equal(case.circular.angle_deg, circle_columns()["angle_deg"])


def write_raw(folder, axis_text, csv_text):
    folder.mkdir()
    (folder / "axis.toml").write_text(axis_text)
    (folder / "circular.csv").write_text(csv_text)
    return folder


GOOD_CSV = "angle_deg,deviation_um,direction\n0,1.0,1\n90,2.0,1\n180,0.5,1\n"


@pytest.mark.parametrize("edit, row, column", [
    (lambda a: a["circular"].pop("radius_mm"), None, "circular.radius_mm"),
    (lambda a: a["circular"].update(radius_mm=-1.0), None, "circular.radius_mm"),
    (lambda a: a["circular"].update(axes=["X", "X"]), None, "circular.axes"),
    (lambda a: a["circular"].update(axes=["X", "toolongname"]), None, "circular.axes"),
    (lambda a: a["circular"].update(center_mm=[1.0]), None, "circular.center_mm"),
    (lambda a: a["axes"]["X"]["screw"].update(lead_mm=0.0), None, "axes.X.screw.lead_mm"),
    (lambda a: a["axes"]["X"].update(spindle={"rpm": 1.0}), None, "axes.X.spindle"),
    (lambda a: a["axes"].update(Z={"screw": {"lead_mm": 1.0}}), None, "axes.Z"),
    (lambda a: a.update(screw={"lead_mm": 1.0}), None, "screw"),
])
def test_axis_toml_refusals(tmp_path, edit, row, column):
    axis = {**AXIS, "circular": dict(AXIS["circular"]),
            "axes": {k: {t: dict(v) for t, v in a.items()} for k, a in AXIS["axes"].items()}}
    edit(axis)
    folder = write_raw(tmp_path / "c", tomli_w.dumps(axis), GOOD_CSV)
    with pytest.raises(CaseError) as error:
        read_case(folder)
    assert error.value.column == column and str(folder / "axis.toml") in str(error.value)


@pytest.mark.parametrize("csv, row, column", [
    ("angle_deg,deviation_um\n0,1\n", "1", "direction"),
    ("angle_deg,deviation_um,direction\n0,1,1\n360,1,1\n", "3", "angle_deg"),
    ("angle_deg,deviation_um,direction\n0,1,1\n-1,1,1\n", "3", "angle_deg"),
    ("angle_deg,deviation_um,direction\n0,1,1\n10,nan,1\n", "3", "deviation_um"),
    ("angle_deg,deviation_um,direction\n0,1,2\n", "2", "direction"),
    ("angle_deg,deviation_um,direction\n0,1,1\n90,1,1\n45,1,1\n", "4", "angle_deg"),
    ("angle_deg,deviation_um,direction\n0,1,-1\n90,1,-1\n", "3", "angle_deg"),
    ("angle_deg,deviation_um,direction,run\n0,1,1,0\n", "2", "run"),
    ("angle_deg,deviation_um,direction,time_s\n0,1,1,1\n90,1,1,1\n", "3", "time_s"),
    ("angle_deg,deviation_um,direction\n0,1,1\n120,1,1\n240,1,1\n10,1,1\n", "5", "angle_deg"),
    ("angle_deg,deviation_um,direction\n0,2e5,1\n", "2", "deviation_um"),
])
def test_circular_csv_refusals(tmp_path, csv, row, column):
    folder = write_raw(tmp_path / "c", tomli_w.dumps(AXIS), csv)
    with pytest.raises(CaseError) as error:
        read_case(folder)
    assert (str(error.value.row), error.value.column) == (row, column)
    assert error.value.path == folder / "circular.csv"


def test_circular_case_holds_circular_csv_alone(tmp_path):
    folder = write_raw(tmp_path / "c", tomli_w.dumps(AXIS), GOOD_CSV)
    (folder / "positioning.csv").write_text("target_mm,error_um\n0,1\n")
    with pytest.raises(CaseError, match="alone"):
        read_case(folder)


# Hand-worked ISO 230-4 figures: 8 points 45° apart; the first harmonic (a centring offset
# of 2 µm along the first axis) is the least-squares centre exactly, since 1, cos θ, sin θ,
# cos 2θ and sin 2θ are orthogonal on these points.
# CCW: d = 3 + 2 cos θ + 5 cos 2θ -> about the LSC 3 + 5 cos 2θ: 8, 3, -2, 3, 8, 3, -2, 3.
# CW:  d + 6 sin 2θ            -> 8, 9, -2, -3, 8, 9, -2, -3.
# G_ccw = 10, G_cw = 12, G (both, one centre) = 9 - (-3) = 12, F_max = 9, F_min = -3,
# H = max |6 sin 2θ| = 6.
def test_figures_hand_worked():
    theta = np.radians(ANGLES)
    ccw = 3 + 2 * np.cos(theta) + 5 * np.cos(2 * theta)
    cw = ccw + 6 * np.sin(2 * theta)
    order = np.argsort(-ANGLES % 360)            # clockwise order of the same angles
    figures = circular_figures(np.concatenate((ANGLES, ANGLES[order])),
                               np.concatenate((ccw, cw[order])), np.repeat([1, -1], 8))
    assert figures.as_dict() == pytest.approx({"G_um": 12, "G_ccw_um": 10, "G_cw_um": 12,
                                               "H_um": 6, "F_max_um": 9, "F_min_um": -3})
    assert figures.center_um == pytest.approx((2, 0), abs=1e-12)
    assert figures.radius_um == pytest.approx(3)


def test_one_direction_has_no_hysteresis():
    figures = circular_figures(ANGLES, np.cos(2 * np.radians(ANGLES)), np.ones(8))
    assert figures.H_um is None and figures.G_cw_um is None
    assert figures.G_ccw_um == pytest.approx(2)


# A single 10 µm spike at 0° on 8 points: the LSC moves 2.5 µm towards it, G about it is
# 7.5 + 2.5 cos 45° = 9.268; the minimum zone moves 5 µm: G = 5 + 5 cos 45° = 8.536.
def test_minimum_zone_hand_worked():
    spike = np.zeros(8)
    spike[0] = 10.0
    assert circular_figures(ANGLES, spike, np.ones(8)).G_um == pytest.approx(
        7.5 + 2.5 * math.sqrt(0.5))
    assert minimum_zone_um(ANGLES, spike) == pytest.approx(5 + 5 * math.sqrt(0.5))
    both = np.concatenate((spike, np.zeros(8)))
    figures = minimum_zone_figures(np.tile(ANGLES, 2), both, np.repeat([1.0, -1.0], 8))
    assert figures["G_ccw_mz_um"] == pytest.approx(5 + 5 * math.sqrt(0.5))
    assert figures["G_cw_mz_um"] == pytest.approx(0.0, abs=1e-9)
    # both paths about one centre: 10 and 0 µm at the same angle 0° whatever the centre,
    # and every sample within [0, 10] about the nominal one: G = 10
    assert figures["G_mz_um"] == pytest.approx(10.0)


@pytest.mark.parametrize("argv, parameter", [
    (["simulate", "circular", "OUT", "--radius-mm", "-1"], "--radius-mm"),
    (["simulate", "circular", "OUT", "--center-mm", "1,2,3"], "--center-mm"),
    (["simulate", "circular", "OUT", "--samples-per-turn", "2"], "--samples-per-turn"),
    (["simulate", "circular", "OUT", "--step-ms", "0"], "--step-ms"),
    (["simulate", "circular", "OUT", "--set", "X_NpidServo"], "--set X_NpidServo"),
])
def test_simulate_circular_refuses_bad_options(tmp_path, capsys, argv, parameter):
    from feedaxis.cli import main

    argv = [str(tmp_path / "out") if a == "OUT" else a for a in argv]
    assert main([*argv, "--json"]) == 2
    error = json.loads(capsys.readouterr().out)
    assert error["parameter"] == parameter
    assert not (tmp_path / "out").exists()


def test_circular_commands_refuse_what_a_circle_cannot_give(tmp_path, capsys):
    from feedaxis.cli import main

    write_case(tmp_path / "c", AXIS, circular=circle_columns())
    case = str(tmp_path / "c")
    assert main(["fit", case, "--add", "backlash", "--json"]) == 2
    assert json.loads(capsys.readouterr().out)["parameter"] == "--add backlash"
    assert main(["fit", case, "--add", "backlash@Z", "--json"]) == 2
    capsys.readouterr()
    assert main(["comp-table", case, "--controller", "linuxcnc", "--out",
                 str(tmp_path / "t.tbl"), "--from-measurement", "--json"]) == 2
    assert json.loads(capsys.readouterr().out)["parameter"] == "--model"
    assert not (tmp_path / "t.tbl").exists()
