"""Case reading per data-format.md: a valid case reads, every bad-input rule is refused
with one message naming file, row and column, exit code 2, and nothing written."""
import numpy as np
import pytest

from feedaxis.case import CaseError, read_case
from feedaxis.cli import main

AXIS = """name = "test axis"

[screw]
lead_mm = 5.0
length_m = 0.8
diameter_m = 0.034
density_kg_m3 = 7800
specific_heat_J_kgK = 448
expansion_per_K = 11.7e-6
youngs_modulus_Pa = 2.1e11
nut_length_m = 0.212
bearing_length_m = 0.03
support = "fixed-free"
fixed_end_mm = -141.0

[motor]
step_angle_deg = 1.8
error_period_steps = 4
"""
POSITIONING = """# laser run, comment line
target_mm,error_um,direction,run,time_s,ambient_C
0.0,1.0,+1,1,10,20.1
100.0,0.5,+1,1,20,20.1
100.0,0.9,-1,1,30,20.2
0.0,1.2,-1,1,40,20.2
"""
DUTY = """start_s,duration_s,feed_mm_min,from_mm,to_mm
0,30,6000,0,500
30,20,0,0,0
50,10,3000,0,100
"""
TRACKING = """time_s,reference_mm,actual_mm,disturbance_N
0.000,0.0,0.0,0
0.001,0.1,0.09,5
0.002,0.2,0.19,5
"""


def write(folder, files):
    folder.mkdir()
    for name, text in files.items():
        (folder / name).write_text(text)
    return folder


@pytest.fixture
def good(tmp_path):
    return {"axis.toml": AXIS, "positioning.csv": POSITIONING, "duty.csv": DUTY,
            "tracking.csv": TRACKING}


def test_valid_case_reads_every_column(tmp_path, good):
    case = read_case(write(tmp_path / "case", good))
    assert case.axis.lead_mm == 5.0 and case.axis.motor["error_period_steps"] == 4
    assert case.axis.screw["support"] == "fixed-free"
    p = case.positioning
    np.testing.assert_array_equal(p.target_mm, [0, 100, 100, 0])
    np.testing.assert_array_equal(p.direction, [1, 1, -1, -1])
    np.testing.assert_array_equal(p.run, [1, 1, 1, 1])
    np.testing.assert_array_equal(p.time_s, [10, 20, 30, 40])
    assert p.bidirectional and case.is_thermal
    assert [s.start_s for s in case.duty.segments] == [0, 30, 50]
    assert case.duty.segments[1].feed_mm_min == 0 and case.duty.end_s == 60
    np.testing.assert_array_equal(case.tracking.disturbance_N, [0, 5, 5])


def test_missing_direction_means_plus(tmp_path, good):
    good["positioning.csv"] = "target_mm,error_um\n0,1\n1,2\n"
    del good["duty.csv"]
    case = read_case(write(tmp_path / "case", good))
    np.testing.assert_array_equal(case.positioning.direction, [1, 1])
    assert not case.positioning.bidirectional


def replace(name, old, new):
    def mutate(files):
        assert old in files[name], (name, old)
        files[name] = files[name].replace(old, new, 1)
    return mutate


def drop(name):
    def mutate(files):
        del files[name]
    return mutate


# (rule, mutation, file, row, column) -- row/column None where the rule has none
BAD_INPUT = [
    ("axis.toml missing", drop("axis.toml"), "axis.toml", None, None),
    ("axis.toml not TOML", replace("axis.toml", "lead_mm = 5.0", "lead_mm = = 5"), "axis.toml", 4, None),
    ("unit-less key", replace("axis.toml", "lead_mm = 5.0", "lead_mm = 5.0\nlead = 5.0"), "axis.toml", 5, "screw.lead"),
    ("unknown key", replace("axis.toml", "length_m", "length_in"), "axis.toml", 5, "screw.length_in"),
    ("unknown top-level key", replace("axis.toml", 'name = "test axis"', 'name = "a"\nowner = "b"'), "axis.toml", 2, "owner"),
    ("unknown table", replace("axis.toml", "[motor]", "[spindle]"), "axis.toml", 16, "spindle"),
    ("lead of zero", replace("axis.toml", "lead_mm = 5.0", "lead_mm = 0.0"), "axis.toml", 4, "screw.lead_mm"),
    ("lead missing", replace("axis.toml", "lead_mm = 5.0\n", ""), "axis.toml", None, "screw.lead_mm"),
    ("negative length", replace("axis.toml", "length_m = 0.8", "length_m = -0.8"), "axis.toml", 5, "screw.length_m"),
    ("text for a number", replace("axis.toml", "diameter_m = 0.034", 'diameter_m = "34 mm"'), "axis.toml", 6, "screw.diameter_m"),
    ("nan in axis", replace("axis.toml", "density_kg_m3 = 7800", "density_kg_m3 = nan"), "axis.toml", 7, "screw.density_kg_m3"),
    ("unknown support", replace("axis.toml", '"fixed-free"', '"clamped"'), "axis.toml", 13, "screw.support"),
    ("fractional steps", replace("axis.toml", "error_period_steps = 4", "error_period_steps = 4.5"), "axis.toml", 18, "motor.error_period_steps"),
    ("missing required column", replace("positioning.csv", "target_mm,error_um,", "target_mm,"), "positioning.csv", "1 (line 2)", "error_um"),
    ("unknown column", replace("positioning.csv", "ambient_C", "ambient_F"), "positioning.csv", "1 (line 2)", "ambient_F"),
    ("duplicate column", replace("positioning.csv", "direction,run,", "direction,target_mm,"), "positioning.csv", "1 (line 2)", "target_mm"),
    ("non-numeric value", replace("positioning.csv", "100.0,0.5", "100.0,abc"), "positioning.csv", "3 (line 4)", "error_um"),
    ("NaN", replace("positioning.csv", "100.0,0.5", "100.0,nan"), "positioning.csv", "3 (line 4)", "error_um"),
    ("infinity", replace("positioning.csv", "0.0,1.2", "inf,1.2"), "positioning.csv", "5 (line 6)", "target_mm"),
    ("missing field", replace("positioning.csv", "100.0,0.5,+1,1,20,20.1", "100.0,0.5,+1,1,20"), "positioning.csv", "3 (line 4)", "ambient_C"),
    ("direction not +-1", replace("positioning.csv", "0.9,-1", "0.9,2"), "positioning.csv", "4 (line 5)", "direction"),
    ("run not a whole number", replace("positioning.csv", "+1,1,20", "+1,1.5,20"), "positioning.csv", "3 (line 4)", "run"),
    ("negative time", replace("positioning.csv", "+1,1,10", "+1,1,-10"), "positioning.csv", "2 (line 3)", "time_s"),
    ("no data rows", replace("positioning.csv", POSITIONING, "target_mm,error_um\n"), "positioning.csv", 2, None),
    ("negative duration", replace("duty.csv", "30,20,0", "30,-20,0"), "duty.csv", 3, "duration_s"),
    ("zero duration", replace("duty.csv", "50,10,3000", "50,0,3000"), "duty.csv", 4, "duration_s"),
    ("overlapping segments", replace("duty.csv", "50,10,3000", "45,15,3000"), "duty.csv", 4, "start_s"),
    ("gap between segments", replace("duty.csv", "50,10,3000", "55,5,3000"), "duty.csv", 4, "start_s"),
    ("first segment not at 0", replace("duty.csv", "0,30,6000", "5,25,6000"), "duty.csv", 2, "start_s"),
    ("negative feed", replace("duty.csv", "50,10,3000", "50,10,-3000"), "duty.csv", 4, "feed_mm_min"),
    ("samples after the duty", replace("positioning.csv", "+1,1,20,", "+1,1,75,"), "positioning.csv", "3 (line 4)", "time_s"),
    ("thermal case without time", lambda f: f.update({"positioning.csv": "target_mm,error_um\n0,1\n"}), "positioning.csv", 1, "time_s"),
    ("tracking time not increasing", replace("tracking.csv", "0.002,0.2", "0.001,0.2"), "tracking.csv", 4, "time_s"),
    ("tracking column missing", replace("tracking.csv", "actual_mm,", ""), "tracking.csv", 1, "actual_mm"),
]


@pytest.mark.parametrize("rule, mutate, file, row, column", BAD_INPUT, ids=[b[0] for b in BAD_INPUT])
def test_bad_input_is_refused_with_file_row_column(tmp_path, good, capsys, rule, mutate, file,
                                                  row, column):
    mutate(good)
    folder = write(tmp_path / "case", good)
    with pytest.raises(CaseError) as raised:
        read_case(folder)
    message = str(raised.value)
    assert file in message
    if row is not None:
        assert f"row {row}," in message or f"row {row}:" in message
    if column is not None:
        assert f"column '{column}'" in message
    out = tmp_path / "model.toml"
    assert main(["fit", str(folder), "--add", "lead_error", "--out", str(out)]) == 2
    stderr = capsys.readouterr().err
    assert stderr.count("\n") == 1 and file in stderr
    assert not out.exists()


def test_case_without_measurements_is_refused(tmp_path):
    folder = write(tmp_path / "case", {"axis.toml": AXIS})
    with pytest.raises(CaseError, match="positioning.csv, tracking.csv or both"):
        read_case(folder)
