"""Compensation tables from a circular test: each axis's table in a controller's format,
read back as the controller applies it, and the circle expected after it."""
from dataclasses import replace

import numpy as np
import pytest

from circular_cases import CENTER_MM, RADIUS_MM, circle_columns, synthetic_case
from feedaxis.comptable import CONTROLLERS, RefusedTable
from feedaxis.comptable.circle import circle_after_um, circle_comp_table, circle_table
from feedaxis.effects import Model
from feedaxis.effects.circular import circular_effects
from feedaxis.fit import fit
from feedaxis.physics import circle


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """Lead slope 0.3 µm/mm on X, 4 µm backlash on Y, 60 µrad squareness, fitted."""
    columns = circle_columns()
    angle, direction = columns["angle_deg"], columns["direction"]
    x_um = 0.3 * circle.axis_positions_mm(angle, RADIUS_MM, CENTER_MM, 0)
    deviation = (circle.radial_um(angle, 0, x_um)
                 + circle.backlash_um(angle, direction, 1, 4.0, RADIUS_MM)
                 + circle.squareness_um(angle, RADIUS_MM, 60.0)
                 + np.random.default_rng(3).normal(0, 0.05, angle.size))
    case = synthetic_case(tmp_path_factory.mktemp("tables") / "c", deviation, columns)
    effects = circular_effects(case.axis)
    model = Model([effects["lead_error@X"], effects["backlash@Y"], effects["squareness"]])
    return case, fit(model, case, kind="circular").fitted_model()


@pytest.mark.parametrize("controller", ["linuxcnc", "siemens", "heidenhain"])
def test_each_axis_table_shrinks_the_circle(fitted, controller, tmp_path):
    case, model = fitted
    for axis, effect in (("X", "lead_error@X"), ("Y", "backlash@Y")):
        files, report = circle_comp_table(case, model, controller, tmp_path / f"{axis}.tab",
                                          axis)
        assert report["included"] == [effect] and "squareness" in report["excluded"]
        g, h = report["figures"]["G_um"], report["figures"]["H_um"]
        assert g["after_um"] < g["before_um"] - 2.0, (axis, g)   # the ellipse 6 µm, B 4 µm
        if axis == "Y":
            assert h["after_um"] < 0.3 * h["before_um"], h       # backlash is hysteresis
        assert report["first_mm"] <= CENTER_MM["XY".index(axis)] - RADIUS_MM
        assert report["last_mm"] >= CENTER_MM["XY".index(axis)] + RADIUS_MM
        assert tmp_path / f"{axis}.tab" in files


def test_both_tables_leave_the_squareness(fitted):
    """After X's and Y's tables the circle is the squareness's ellipse, α R / 2 = 0.6 µm."""
    case, model = fitted
    controller = CONTROLLERS["linuxcnc"]
    after = case
    for axis in ("X", "Y"):
        table, _ = circle_table(case, model, axis, controller)
        applied = controller.read(controller.write(table, "0"))
        after = after.with_samples("circular", replace(
            after.circular, deviation_um=circle_after_um(after, model, axis, applied)))
    left = after.circular.deviation_um - circle.squareness_um(after.circular.angle_deg,
                                                              RADIUS_MM, 60.0)
    assert np.std(left) < 0.12   # the 0.05 µm noise and the play crossed at the reversals


def test_a_table_that_would_raise_g_is_refused(fitted, tmp_path):
    case, model = fitted
    wrong = Model(model.effects, {**model.values,
                                  "backlash@Y": {**model.values["backlash@Y"],
                                                 "backlash_um": -8.0}})
    with pytest.raises(RefusedTable, match="G would rise"):
        circle_comp_table(case, wrong, "linuxcnc", tmp_path / "Y.tbl", "Y")
    files, report = circle_comp_table(case, wrong, "linuxcnc", tmp_path / "Y.tbl", "Y",
                                      force=True)
    assert any("G would rise" in w for w in report["warnings"])
