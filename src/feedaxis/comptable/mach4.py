"""Mach4 screw mapping (Machine Calibration plugin, Linear Compensation).

Evenly spaced points from a start point (the most negative position) over a length in +;
the number of points counts both ends; the error at each point, one map for both
directions in older builds (after 2107) and one per direction after build 4780 (MachMotion
support, "Mach 4 Screw Mapping"). The error is entered as measured − expected, in machine
units (mm); the sign rests on the plugin's wording, no worked example was found. Written as
the plugin's inputs followed by one line per point.
"""
from __future__ import annotations

import numpy as np

from ..linefile import LineError, number
from .base import Controller, UM_PER_MM, assignments, check_equidistant, check_points, require
from .table import CompTable

NAME = "mach4"
MAX_POINTS = None
EQUIDISTANT = True
DEFAULT_AXIS_ID = "X"
AXIS_ID = r"[XYZABCxyzabc]"  # one of Mach4's six coordinated axes
SIGN = "error = measured - expected (mm), per direction"
LOAD = ("Configure > Plugins > Machine Calibration > Linear Compensation: select the motor, "
        "Modify Inputs: start point, length, number of points; then the errors per point "
        "(positive and negative map on builds after 4780)")
PATTERN = r"^([A-Za-z ]+?)\s*=\s*(\S+)"


def write(table, axis_id=DEFAULT_AXIS_ID):
    """The screw map inputs for ``axis_id`` and one ``point position + - `` line per point."""
    check_points(table, MAX_POINTS, NAME)
    check_equidistant(table, NAME)
    lines = [f"Axis = {axis_id}", f"Start point = {table.position_mm[0]:.6f}",
             f"Length = {np.ptp(table.position_mm):.6f}", f"Number of points = {table.size}",
             "# point  position_mm  error_positive_mm  error_negative_mm"]
    lines += [f"{i} {x:.6f} {f / UM_PER_MM:.6f} {r / UM_PER_MM:.6f}"
              for i, (x, f, r) in enumerate(zip(table.position_mm, table.forward_um,
                                                table.reverse_um))]
    return "\n".join(lines) + "\n"


def read(text, path="screwmap.txt"):
    """The map the plugin applies: points from start, length and count, errors per line."""
    found = assignments(text, path, PATTERN)
    values = {}
    for key in ("Start point", "Length", "Number of points"):
        value, line = require(found, key, path)
        values[key] = number(value, path, line, key)
    count = int(values["Number of points"])
    if count < 2 or values["Length"] <= 0:
        raise LineError(path, "needs at least 2 points over a length > 0",
                        found["Number of points"][1], "Number of points")
    rows = [(line_number, line.split()) for line_number, line in enumerate(text.splitlines(), 1)
            if line.strip() and not line.lstrip().startswith("#") and "=" not in line]
    if len(rows) != count:
        raise LineError(path, f"{len(rows)} point lines for {count} points",
                        found["Number of points"][1], "Number of points")
    for line_number, fields in rows:
        if len(fields) != 4:
            raise LineError(path, "expected 'point position error_positive error_negative'",
                            line_number)
    errors = np.array([[number(v, path, line_number, name) for v, name in
                        zip(fields[2:], ("error_positive_mm", "error_negative_mm"))]
                       for line_number, fields in rows])
    position_mm = values["Start point"] + values["Length"] * np.linspace(0.0, 1.0, count)
    return CompTable(position_mm, errors[:, 0] * UM_PER_MM, errors[:, 1] * UM_PER_MM, "file")


CONTROLLER = Controller(NAME, write, read, MAX_POINTS, EQUIDISTANT, DEFAULT_AXIS_ID, SIGN, LOAD,
                        axis_id_pattern=AXIS_ID)
