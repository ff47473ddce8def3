"""Pitch-error compensation tables for CNC controllers, from the fitted model or the
measured means, verified on the measured case before they are loaded.

One module per controller, each defining its :class:`~.base.Controller` (``CONTROLLER``:
``write(table, axis_id) -> text``, ``read(text) -> CompTable`` as that controller applies
it, its limits, grid rules, sign convention, how to load the file, companion files and
notes), registered in :data:`CONTROLLERS`, which the command line and its help read.
"""
from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..iso230 import target_clusters
from . import beckhoff, fanuc, heidenhain, linuxcnc, mach4, siemens
from .base import Controller
from .table import (GRID_DECIMALS, NEVER_IN_TABLE, TABLE_TOLERANCE_UM, CompTable,
                    default_spacing_mm, from_measurement, from_model, grid_mm, lean_table)
from .verify import between_targets, verify

# The one registry of controllers (the command line's choices and help read it). The table's
# safety and the positioning samples load when a table is made (the fit behind them takes
# seconds to import), so the command line can read this registry at start-up.
CONTROLLERS = {module.CONTROLLER.name: module.CONTROLLER
               for module in (linuxcnc, siemens, fanuc, heidenhain, beckhoff, mach4)}
POSITIONING_FILE = "positioning.csv"
MAX_TABLE_POINTS = 100_000  # of a controller without its own limit: a file of some MB


def check_case(case):
    """``case`` when it holds what a table is made from (positioning.csv), else
    :class:`InputError`."""
    if case.positioning is None:
        raise InputError(f"a compensation table needs {POSITIONING_FILE}", path=case.folder)
    return case
# A controller without a point limit gets at most a point every lead / 16 from the model:
# a once-per-revolution error followed within 2 % of its amplitude (1 − cos(π/16))
LEAN_POINTS_PER_LEAD = 16


def build_table(case, model, controller, spacing_mm=None, from_measured=False,
                tolerance_um=TABLE_TOLERANCE_UM):
    """The table for ``controller`` on ``case``: from ``model`` (default) or the measured
    means; with the :class:`~.table.LeanTable` record of a model's table chosen lean (None
    otherwise).

    The points are equidistant over the measured targets, every ``spacing_mm`` when it is
    given; from the model, by default the fewest that reproduce it within ``tolerance_um``
    under the controller's grid rules (:func:`.table.lean_table`; at most the count at lead
    / 8, within the controller's point limit). A table from the measurement on a controller
    that takes free positions uses the targets themselves unless ``spacing_mm`` is given.
    """
    chosen = CONTROLLERS[controller]
    target_mm = case.positioning.target_mm
    first_mm, last_mm = _span_mm(chosen, target_mm)
    if spacing_mm is not None:
        check_spacing(chosen, spacing_mm, last_mm - first_mm)
    if from_measured:
        count = target_clusters(target_mm)[0].size
        if count < 2:
            raise InputError(f"a table from the measurement needs at least two targets; every "
                             f"sample is at {target_mm[0]:g} mm", column="target_mm",
                             path=case.folder / POSITIONING_FILE)
        if spacing_mm is None and not chosen.equidistant:
            return from_measurement(case), None
        spacing_mm = spacing_mm or (target_mm.max() - target_mm.min()) / max(count - 1, 1)
        return from_measurement(case, _grid(chosen, first_mm, last_mm, spacing_mm)), None
    if spacing_mm:
        return from_model(case, model, _grid(chosen, first_mm, last_mm, spacing_mm)), None
    most = chosen.max_points or _count_grid(chosen, first_mm, last_mm, int(np.ceil(
        (last_mm - first_mm) / case.axis.lead_mm * LEAN_POINTS_PER_LEAD)) + 1).size
    lean = lean_table(case, model, lambda count: _count_grid(chosen, first_mm, last_mm, count),
                      most, (first_mm, last_mm), tolerance_um)
    return lean.table, lean


def _count_grid(controller, first_mm, last_mm, count):
    """At most ``count`` equidistant points over the span under the controller's grid rules
    (a grid through 0 mm may need one interval more), spaced by whole micrometres."""
    for intervals in (count - 1, count - 2):
        spacing_mm = np.ceil((last_mm - first_mm) / max(intervals, 1) * 1e3) / 1e3
        points = _grid(controller, first_mm, last_mm, spacing_mm)
        if points.size <= count or intervals <= 1:
            return points
    return points


def safe_table(case, model, position_mm):
    """The table of ``model`` at ``position_mm`` (:func:`.table.from_model`) without the
    effects a table must not use (:func:`.safety.unsafe_effects`), which ``excluded`` names
    with why."""
    from . import safety

    unsafe = safety.unsafe_effects(case, model)
    table = from_model(case, safety.usable_model(model, unsafe), position_mm)
    return replace(table, excluded={**safety.reasons_by_effect(unsafe), **table.excluded})


def check_spacing(controller, spacing_mm, span_mm):
    """Refuse a ``--spacing-mm`` that is not finite and > 0, longer than the travel the
    table covers (its points would lie beyond the stroke), or so short that the table
    would take more points than the controller (or any file: :data:`MAX_TABLE_POINTS`)."""
    if not (math.isfinite(spacing_mm) and spacing_mm >= 10.0 ** -GRID_DECIMALS):
        raise InputError(f"must be a number of at least {10.0 ** -GRID_DECIMALS:g} mm, got "
                         f"{spacing_mm:g}", parameter="--spacing-mm")
    if spacing_mm > span_mm:
        raise InputError(f"{spacing_mm:g} mm is longer than the {span_mm:g} mm the table "
                         "covers: its last point would lie beyond the measured travel",
                         parameter="--spacing-mm")
    limit = controller.max_points or MAX_TABLE_POINTS
    if span_mm / spacing_mm + 1 > limit:
        raise InputError(f"{span_mm / spacing_mm + 1:.0f} table points over {span_mm:g} mm; "
                         f"{controller.name} takes at most {limit}: choose a larger spacing",
                         parameter="--spacing-mm")


def _span_mm(controller, target_mm):
    """(first, last) position the table covers: the targets, and 0 mm for a controller that
    counts its points from the reference position there (``grid_through_zero``)."""
    first_mm, last_mm = float(target_mm.min()), float(target_mm.max())
    if controller.grid_through_zero:
        return min(first_mm, 0.0), max(last_mm, 0.0)
    return first_mm, last_mm


def _grid(controller, first_mm, last_mm, spacing_mm):
    """Table points every ``spacing_mm`` over the span from :func:`_span_mm`, through 0 mm
    for a ``grid_through_zero`` controller."""
    spacing_mm = round(float(spacing_mm), 6)
    if controller.grid_through_zero and spacing_mm > 0:
        first_mm = spacing_mm * np.floor(round(first_mm / spacing_mm, 9))
    return grid_mm(first_mm, last_mm, spacing_mm)


class RefusedTable(InputError):
    """A table that is not safe to load (exit 2, nothing written): ``reasons`` say why,
    ``report`` holds the figures."""

    def __init__(self, out_path, reasons, report, left_out=()):
        lines = [*reasons, f"the table {'without them ' if left_out else ''}would give:",
                 *_figure_lines(report)]
        lines.append("fit a model the data determine (feedaxis diagnose CASE names what they "
                     "support), or add --force to write the table anyway")
        super().__init__(f"refused, nothing written to {out_path}:\n  " + "\n  ".join(lines))
        self.reasons, self.report = reasons, report

    def as_json(self):
        return {**super().as_json(), "refused": self.reasons, "report": self.report}


def comp_table(case, model, controller, out_path, spacing_mm=None, from_measured=False,
               axis_id=None, force=False, tolerance_um=TABLE_TOLERANCE_UM):
    """The ``controller`` file for ``out_path``, read back as the controller does and verified.

    Effects a table must not use (:func:`.safety.unsafe_effects`) are left out. The table is
    refused with :class:`RefusedTable` when that left something out or when its verification
    expects it to make the axis worse (:func:`.safety.refusals`); ``force`` returns it anyway,
    with warnings saying what it risks.

    Returns ({path: text} of the files to write, ``out_path`` and any companion such as
    a controller's ``companions``; the report dict for printing and ``--json``).
    """
    from . import safety

    chosen = CONTROLLERS[controller]
    axis_id = checked_axis_id(chosen, axis_id)
    unsafe = safety.unsafe_effects(case, model)
    usable = safety.usable_model(model, unsafe)
    table, lean = build_table(case, usable, controller, spacing_mm, from_measured, tolerance_um)
    text = chosen.write(table, axis_id)
    applied = chosen.read(text)
    out_path = Path(out_path)
    files = {**chosen.companions(out_path, axis_id), out_path: text}
    report = {"controller": controller, "source": table.source, "points": table.size,
              "first_mm": float(table.position_mm[0]), "last_mm": float(table.position_mm[-1]),
              "spacing_mm": table.spacing_mm, "direction_dependent": table.bidirectional,
              "included": list(table.included),
              "excluded": {} if from_measured else {**safety.reasons_by_effect(unsafe),
                                                    **table.excluded},
              "sign": chosen.sign, "load": chosen.load, **verify(case, applied),
              "between_targets": between_targets(case, usable, applied),
              "files": [str(path) for path in files]}
    if chosen.suffix and out_path.suffix.upper() != chosen.suffix:
        report["warnings"].append(
            f"{chosen.name} finds a compensation table by its {chosen.suffix} ending: "
            f"{out_path.name} will not be loaded; name it {out_path.stem}{chosen.suffix}")
    report["tolerance_um"] = None if lean is None else lean.tolerance_um
    report["deviation_um"] = None if lean is None else lean.deviation_um
    report["notes"] = _lean_notes(lean, chosen) + _notes(table, chosen)
    if from_measured and unsafe:
        report["notes"].append(f"the model's view between the targets leaves out "
                               f"{', '.join(unsafe)}: the data cannot determine them")
        unsafe = {}
    reasons = safety.refusals(report, unsafe)
    if reasons and not force:
        raise RefusedTable(out_path, reasons, {**report, "files": []}, list(unsafe))
    if force:
        report["warnings"] += safety.forced_warnings(report, unsafe)
    return files, report


def checked_axis_id(controller, axis_id):
    """``axis_id`` (default: the controller's), refused unless it is what the controller's
    file holds there (``controller.axis_id_pattern``): a newline or a word more would write
    a line of the user's into the controller file."""
    if axis_id is None:
        return controller.default_axis_id
    if not re.fullmatch(controller.axis_id_pattern, axis_id):
        raise InputError(f"{axis_id!r} is not an axis of a {controller.name} file: expected "
                         f"{controller.axis_id_pattern} (default "
                         f"{controller.default_axis_id})", parameter="--axis-id")
    return axis_id


def _lean_notes(lean, controller):
    """How the model's table was sized: the tolerance and what it reached."""
    if lean is None:
        return []
    held = ", ".join(lean.table.included) or "nothing"
    if lean.reached:
        return [f"{lean.table.size} points: the fewest that reproduce the model ({held}) "
                f"within {lean.tolerance_um:g} µm between them (largest deviation "
                f"{lean.deviation_um:.3g} µm, before the controller's rounding); --spacing-mm "
                "sets the spacing, --tolerance-um the tolerance"]
    limit = (f"{controller.name} takes at most {controller.max_points}" if controller.max_points
             else f"a point every lead / {LEAN_POINTS_PER_LEAD} at most")
    return [f"{lean.table.size} points, the most allowed here ({limit}), leave up to "
            f"{lean.deviation_um:.3g} µm of the model ({held}) between them, over the "
            f"{lean.tolerance_um:g} µm tolerance"]


def _notes(table, controller):
    """What limits this table: figures in-sample for measured means, the controller's
    reference and machine data (the point limit is said by :func:`_lean_notes`)."""
    notes = []
    if table.source == "measurement":
        notes.append("the table is the measured means at the targets: the figures after are "
                     "in-sample there (optimistic); between the targets it is blind")
    return notes + controller.notes(table)


def summary_lines(report):
    """The comp-table result for the terminal: the table, what went in, before and after."""
    lines = [f"{report['controller']} table from the {report['source']}: {report['points']} "
             f"points {report['first_mm']:g} to {report['last_mm']:g} mm every "
             f"{report['spacing_mm']:.4g} mm"
             + (", direction-dependent" if report["direction_dependent"] else ""),
             f"  in the table: {', '.join(report['included']) or '(nothing)'}"]
    lines += [f"  left out {name}: {reason}" for name, reason in report["excluded"].items()]
    lines += [f"  sign: {report['sign']}", f"  load: {report['load']}", "",
              *_figure_lines(report)]
    lines += [f"note: {note}" for note in report["notes"]]
    lines += [f"warning: {warning}" for warning in report["warnings"]]
    lines += [f"written: {path}" for path in report["files"]]
    return "\n".join(lines)


def _figure_lines(report):
    """The ISO 230-2 figures expected before and after the table, and the model's view
    between the targets."""
    title = f"{report.get('standard', 'ISO 230-2')} figure, expected"
    names = [f"{f['name']} ({f['center']})" if "center" in f else f["name"]
             for f in report["figures"].values()]
    width = max(34, *map(len, names))
    lines = [f"{title:{width}s} {'before':>9s} {'after':>9s}  (µm)"]
    lines += [f"{name:{width}s} {f['before_um']:9.3f} {f['after_um']:9.3f}"
              for name, f in zip(names, report["figures"].values())]
    between = report.get("between_targets")
    if between:
        lines.append(f"{'between targets (model), P-V':34s} {between['pv_before_um']:9.3f} "
                     f"{between['pv_after_um']:9.3f}")
    return lines
