"""A model's table has the fewest points that reproduce the model within the tolerance under
each controller's grid rules (issue 33): a linear model (lead error and backlash) gets the
controller's minimum of two points; a once-per-revolution eccentricity gets as many as it
needs, the tolerance is met between the points of the file as the controller reads it, and
where the controller's point limit stops the search the output says how far it fell short."""
import json

import numpy as np
import pytest

import synthetic as syn
from feedaxis.case import read_case
from feedaxis.cli import main
from feedaxis.comptable import CONTROLLERS
from feedaxis.comptable.table import TABLE_TOLERANCE_UM, position_error_um
from feedaxis.effects import CATALOG, Model

LINEAR = {"lead_error": {"offset_um": 2.0, "slope_um_per_mm": -0.02},
          "backlash": {"backlash_um": 4.0}}
PERIODIC = {**LINEAR, "assembly_eccentricity": {"cos_um": 0.3, "sin_um": -0.2}}
# the largest rounding of a value in each controller's file (µm): Fanuc's 1 µm detection
# unit (and its increments add up), Beckhoff's 0.1 µm, 10^-6 or 10^-7 mm for the others
ROUNDING_UM = {"linuxcnc": 1e-4, "siemens": 1e-3, "fanuc": 1.0, "heidenhain": 1e-3,
               "beckhoff": 0.05, "mach4": 1e-3}


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """81 targets 4.9 mm apart from 0 mm up (Fanuc's grid through 0 mm then needs no point
    below it), a 10 mm lead, 3 bidirectional cycles (the values do not matter: the tables
    below come from models written by hand)."""
    return syn.staggered_case(tmp_path_factory.mktemp("lean") / "case", 2, (0.3, -0.2), 0.2,
                              first_mm=0.5)


def table(capsys, case, values, controller, out):
    """(the model, comp-table's JSON report) of a model written by hand with ``values``."""
    model = Model([CATALOG[name] for name in values], values)
    path = out.parent / f"{out.name}.toml"
    path.write_text(model.to_toml())
    assert main(["comp-table", str(case), "--model", str(path), "--controller", controller,
                 "--out", str(out), "--json"]) == 0
    return model, json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("controller", sorted(CONTROLLERS))
def test_a_linear_model_gets_the_controllers_minimum(case, tmp_path, capsys, controller):
    _, report = table(capsys, case, LINEAR, controller, tmp_path / "t")
    assert report["points"] == 2
    assert report["tolerance_um"] == TABLE_TOLERANCE_UM
    assert report["deviation_um"] <= TABLE_TOLERANCE_UM
    assert f"within {TABLE_TOLERANCE_UM:g} µm" in report["notes"][0]


@pytest.mark.parametrize("controller", sorted(CONTROLLERS))
def test_the_tolerance_is_met_between_the_points_as_the_controller_reads_them(
        case, tmp_path, capsys, controller):
    """The eccentricity (0.36 µm) needs points; the file read back by the controller's
    reader stays within the tolerance of the model everywhere over the targets (plus the
    file's rounding), or the output says by how much it could not."""
    model, report = table(capsys, case, PERIODIC, controller, tmp_path / "t")
    module = CONTROLLERS[controller]
    applied = module.read((tmp_path / "t").read_text())
    assert report["points"] > 2   # (Fanuc's reader adds the point an increment starts from)
    samples = read_case(case)
    dense_mm = np.linspace(samples.positioning.target_mm.min(),
                           samples.positioning.target_mm.max(), 5001)
    left_um = np.concatenate([position_error_um(samples, model, dense_mm, direction)
                              - applied.error_um(dense_mm, direction) for direction in (1, -1)])
    # Siemens and Fanuc hold values relative to the reference point: one constant apart
    worst = float(np.max(np.abs(left_um - np.median(left_um))))
    if report["deviation_um"] <= TABLE_TOLERANCE_UM:
        assert worst <= TABLE_TOLERANCE_UM + ROUNDING_UM[controller]
        assert "the fewest" in report["notes"][0]
    else:
        assert report["points"] == module.max_points
        assert "the most allowed here" in report["notes"][0]
        assert worst <= report["deviation_um"] + ROUNDING_UM[controller]
