"""docs/case-format.md says what the reader enforces: every axis.toml key and CSV column,
with the range of feedaxis.case; the laser example shipped with the package (axis.toml +
X-axis.rtl) is what its generator writes, imports, and gives back the parameters it was
generated from."""
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from feedaxis import case as case_format
from feedaxis import circular_case
from feedaxis.case import read_axis, read_case
from feedaxis.cli import main
from feedaxis.effects import CATALOG, Model
from feedaxis.measurement import positioning, tracking
from feedaxis.examples import (LASER_BACKLASH_UM, LASER_EXAMPLE, LASER_LEAD, LASER_NOISE_UM,
                               laser_example_rtl)
from feedaxis.fit import fit

PAGE = Path(__file__).resolve().parents[2] / "docs" / "case-format.md"


def rows(section):
    """{first cell without backticks: row} of the tables under the heading ``section``."""
    text = PAGE.read_text(encoding="utf-8").split(f"\n{section}\n", 1)[1]
    text = re.split(r"\n#{2,3} ", text, maxsplit=1)[0]
    found = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if line.startswith("| `"):
            found[cells[0].strip("`")] = cells
    return found


def range_text(name):
    low, high = case_format.PHYSICAL_RANGE[name]
    return f"{low:g} to {high:g}"


def test_every_axis_key_is_listed_with_the_range_the_reader_enforces():
    listed = rows("## axis.toml")
    expected = {"name"} | {f"[{table}] {key}" for table, keys in case_format.TABLES.items()
                           for key in keys}
    assert set(listed) == expected
    for table, keys in case_format.TABLES.items():
        for key, rule in keys.items():
            cells = listed[f"[{table}] {key}"]
            if key in case_format.PHYSICAL_RANGE:
                assert cells[2].startswith(range_text(key)), (key, cells[2])
            else:
                choices = {"support": case_format.SUPPORTS,
                           "controller": case_format.CONTROLLERS}[rule]
                assert all(f'`"{choice}"`' in cells[2] for choice in choices), key
    for controller, keys in case_format.SERVO_REQUIRED.items():
        for key in keys:
            assert f'required for `"{controller}"`' in listed[f"[servo] {key}"][3] \
                or f'`"{controller}"`' in listed[f"[servo] {key}"][3], (controller, key)
    assert "required" in listed["[servo] force_constant_N_per_V"][3]


@pytest.mark.parametrize("section, spec", [
    ("### positioning.csv", positioning.POSITIONING_COLUMNS),
    ("### duty.csv", case_format.DUTY_COLUMNS),
    ("### tracking.csv", tracking.TRACKING_COLUMNS),
    ("### circular.csv", circular_case.CIRCULAR_COLUMNS)])
def test_every_csv_column_is_listed_with_its_range(section, spec):
    listed = rows(section)
    assert set(listed) == set(spec)
    for name, required in spec.items():
        cells = listed[name]
        if name in case_format.PHYSICAL_RANGE:
            low, high = case_format.PHYSICAL_RANGE[name]
            assert range_text(name) in cells[2] or (
                low == 0 and f"up to {high:g}" in cells[2]), (name, cells[2])
        assert (cells[3] == "yes") == required, name


def test_every_circular_key_is_listed():
    listed = rows("## Circular tests")
    assert {f"[circular] {key}" for key in circular_case.CIRCULAR_KEYS} <= set(listed)
    assert listed["[circular] radius_mm"][2].startswith(range_text("radius_mm"))


def test_the_shipped_laser_example_is_its_generator_output():
    assert (LASER_EXAMPLE / "X-axis.rtl").read_bytes() == laser_example_rtl().encode()
    assert read_axis(LASER_EXAMPLE / "axis.toml").lead_mm == 10.0


def test_the_shipped_laser_example_gives_back_its_parameters(tmp_path, capsys):
    for name in ("X-axis.rtl", "axis.toml"):
        shutil.copy2(LASER_EXAMPLE / name, tmp_path / name)
    assert main(["import", str(tmp_path / "X-axis.rtl"), "--axis", str(tmp_path / "axis.toml"),
                 "--out", str(tmp_path / "case")]) == 0
    assert "ambient_C, 20.4" in capsys.readouterr().out
    case = read_case(tmp_path / "case")
    assert case.positioning.size == 110 and np.all(case.positioning.ambient_C == 20.4)
    result = fit(Model([CATALOG["lead_error"], CATALOG["backlash"]]), case)
    truth = {"lead_error": LASER_LEAD, "backlash": {"backlash_um": LASER_BACKLASH_UM}}
    for effect, values in truth.items():
        for parameter, value in values.items():
            sigma = result.uncertainties[effect][parameter]
            assert abs(result.model.values[effect][parameter] - value) < 3 * sigma, parameter
    assert result.rms_um == pytest.approx(LASER_NOISE_UM, rel=0.2)
