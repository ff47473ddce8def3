"""An axis's compensation table from a circular test, and the circle expected after it.

A model fitted on a circular case holds effects of each axis (``lead_error@X``,
``backlash@Y``, ...). The table of one axis is that axis's one-axis effects (the catalog
effects they wrap, with the fitted values) over the axis's travel on the circle, built and
written as for a positioning case (:func:`.table.from_model`, the controller's own module).
It is read back as the controller applies it, and the circle after it predicted: the
measured radial deviation less the table's correction at the axis's position and direction
of motion, projected on the radius (e cos θ or e sin θ). The ISO 230-4 figures before and
after decide: a table expected to raise G is refused (nothing written) unless forced.
The machine's effects (squareness, servo mismatch) and an axis's servo effects (a reversal
spike, friction or the plant in its loop) are no position table's: they are left out and
said.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..effects import Model
from ..effects.catalog import Backlash
from ..effects.circular import CircleBacklash, OnAxis, axis_case, axis_index
from ..errors import InputError
from ..iso230_4 import figures_um
from ..measurement.circular import FIGURE_NAMES
from ..physics import circle
from . import CONTROLLERS, RefusedTable, _grid
from .table import default_spacing_mm, from_model

SERVO_REASON = ("it acts in the axis's servo (a reversal spike, friction or the plant of its "
                "loop), not at its positions: no position table removes it")
MACHINE_REASON = "an effect of the machine (both axes), not of one axis's positions"
NO_LEAD_POINTS = 64  # table intervals over the circle's span when the axis's lead is unknown


def axis_model(model, axis):
    """(one-axis Model of ``axis``'s effects in ``model``, {effect: why left out})."""
    effects, values, excluded = [], {}, {}
    for effect in model.effects:
        fitted = model.values[effect.name]
        if isinstance(effect, OnAxis) and effect.axis == axis:
            effects.append(effect.inner)
            values[effect.inner.name] = effect.inner_values(fitted)
        elif isinstance(effect, CircleBacklash) and effect.axis == axis:
            effects.append(Backlash())
            values["backlash"] = {"backlash_um": fitted["backlash_um"]}
        elif effect.axis == axis:
            excluded[effect.name] = SERVO_REASON
        elif effect.axis is None:
            excluded[effect.name] = MACHINE_REASON
    return Model(effects, values), excluded


def circle_table(case, model, axis, controller, spacing_mm=None):
    """(CompTable of ``axis`` for ``controller`` (a Controller), what was left out)."""
    if axis not in case.axis.circular.axes:
        raise InputError(f"name the axis whose table to write, one of the circular case's "
                         f"axes {', '.join(case.axis.circular.axes)}",
                         parameter=f"--circle-axis {axis}" if axis else "--circle-axis")
    one_axis, excluded = axis_model(model, axis)
    view = axis_case(case, axis)
    test = case.axis.circular
    index = axis_index(case, axis)
    first_mm, last_mm = test.center_mm[index] - test.radius_mm, test.center_mm[index] + test.radius_mm
    if spacing_mm is None:
        spacing_mm = (default_spacing_mm(view, controller.max_points, last_mm - first_mm)
                      if "lead_mm" in view.axis.screw else (last_mm - first_mm) / NO_LEAD_POINTS)
    table = from_model(view, one_axis, _grid(controller, first_mm, last_mm, spacing_mm))
    return table, {**excluded, **table.excluded}


def circle_after_um(case, model, axis, applied):
    """The radial deviation (µm) expected after the table ``applied`` (as the controller
    reads it) on ``axis``: measured less the correction projected on the radius.

    The table's mean of its two directions corrects the position; their difference is
    backlash compensation, which moves the motor through the play at the reversal, so it
    takes away the backlash as the model sees it on the circle (crossing the play, late
    by the fitted lag) at the size the table gives.
    """
    samples, test = case.circular, case.axis.circular
    index = axis_index(case, axis)
    position_mm = circle.axis_positions_mm(samples.angle_deg, test.radius_mm, test.center_mm,
                                           index)
    position_um = 0.5 * (applied.error_um(position_mm, 1.0) + applied.error_um(position_mm, -1.0))
    backlash_um = float(np.mean(applied.forward_um - applied.reverse_um))
    lag_deg = next((model.values[e.name]["lag_deg"] for e in model.effects
                    if isinstance(e, CircleBacklash) and e.axis == axis), 0.0)
    shape = circle.backlash_shape(samples.angle_deg, samples.direction, index, test.radius_mm)
    return (samples.deviation_um - circle.radial_um(samples.angle_deg, index, position_um)
            - shape(backlash_um, lag_deg))


def circle_comp_table(case, model, controller, out_path, axis, spacing_mm=None, axis_id=None,
                      force=False):
    """The ``controller`` file of ``axis`` from a model fitted on the circular ``case``.

    Returns ({path: text}, report) as :func:`feedaxis.comptable.comp_table` does; the report's
    ``figures`` are the ISO 230-4 figures before and after. Raises :class:`RefusedTable`
    when the table would raise G (both directions) or holds nothing, unless ``force``.
    """
    chosen = CONTROLLERS[controller]
    table, excluded = circle_table(case, model, axis, chosen, spacing_mm)
    axis_id = axis_id or chosen.default_axis_id
    text = chosen.write(table, axis_id)
    applied = chosen.read(text)
    out_path = Path(out_path)
    files = {**chosen.companions(out_path, axis_id), out_path: text}
    samples = case.circular
    before = figures_um(samples.angle_deg, samples.deviation_um, samples.direction)
    after = figures_um(samples.angle_deg, circle_after_um(case, model, axis, applied),
                       samples.direction)
    figures = {key: {"name": name, "center": centre, "before_um": before[key],
                     "after_um": after[key]}
               for key, (name, centre) in FIGURE_NAMES.items() if before[key] is not None}
    report = {"controller": controller, "axis": axis, "standard": "ISO 230-4",
              "source": "model", "points": table.size,
              "first_mm": float(table.position_mm[0]), "last_mm": float(table.position_mm[-1]),
              "spacing_mm": table.spacing_mm, "direction_dependent": table.bidirectional,
              "included": [f"{name}@{axis}" for name in table.included], "excluded": excluded,
              "sign": chosen.sign, "load": chosen.load, "figures": figures,
              "files": [str(path) for path in files], "notes": [], "warnings": []}
    reasons = []
    if not table.included:
        reasons.append(f"the model holds no effect of axis {axis} a position table can remove")
    if figures["G_um"]["after_um"] > figures["G_um"]["before_um"]:
        reasons.append(f"the circle's G would rise from {figures['G_um']['before_um']:.3f} to "
                       f"{figures['G_um']['after_um']:.3f} µm")
    if reasons and not force:
        raise RefusedTable(out_path, reasons, {**report, "files": []})
    report["warnings"] += reasons
    return files, report
