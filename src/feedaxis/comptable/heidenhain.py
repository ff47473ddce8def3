"""Heidenhain TNC / MANUALplus nonlinear axis-error compensation: a ``.COM`` table with its
``.CMA`` assignment.

``.COM``: column ``AXISPOS`` (the compensation point, mm from the machine datum), a column
named after the axis holding the compensation value (mm) and ``BACKLASH`` holding the value
measured in the negative direction of traverse (technical manual MANUALplus 620, "Entering
compensation values"). ``.CMA``: one column per compensated axis naming the ``.COM`` file, a
``*`` in ``ACTIVE`` activates the line. Older controls take at most 256 entries per table.
The value is written as the deviation (measured − target): the manuals plot and enter
"the error"; no worked example with a sign was found.
"""
from __future__ import annotations

import re

import numpy as np

from ..linefile import LineError, number
from .base import Controller, UM_PER_MM, check_points
from .table import CompTable

NAME = "heidenhain"
MAX_POINTS = 256
EQUIDISTANT = False
DEFAULT_AXIS_ID = "X"
AXIS_ID = r"[A-Za-z][0-9]?"  # an axis letter (X, Y, Z, U, A, ...)
SIGN = "value = measured - target (mm); BACKLASH column: the same in the negative direction"
LOAD = ("copy <name>.COM and the .CMA (e.g. as config.cma) to PLC:\\COMP, activate the line "
        "with * in ACTIVE (or PLC module 9095); nonlinear compensation on (MP730 on older TNC)")

def write(table, axis_id=DEFAULT_AXIS_ID):
    """The ``.COM`` table of ``table`` for axis column ``axis_id``."""
    check_points(table, MAX_POINTS, NAME)
    axis = axis_id.upper()
    lines = [f"BEGIN {axis}.COM MM", f"{'NR':<6}{'AXISPOS':>14}{axis:>14}{'BACKLASH':>14}"]
    lines += [f"{i:<6}{x:>+14.4f}{f / UM_PER_MM:>+14.6f}{r / UM_PER_MM:>+14.6f}"
              for i, (x, f, r) in enumerate(zip(table.position_mm, table.forward_um,
                                                table.reverse_um))]
    return "\n".join(lines + ["[END]"]) + "\n"


def companions(out_path, axis_id=DEFAULT_AXIS_ID):
    """{path: text}: the ``.CMA`` assignment beside ``out_path`` activating it for the axis."""
    axis = axis_id.upper()
    text = "\n".join([f"BEGIN {out_path.stem.upper()}.CMA", f"{'NR':<6}{'ACTIVE':<8}{axis}",
                      f"{0:<6}{'*':<8}{out_path.name}", "[END]"]) + "\n"
    return {out_path.with_suffix(".CMA"): text}


def read(text, path="X.COM"):
    """The compensation of the ``.COM`` part: value in + and (``BACKLASH``) in −."""
    lines = text.splitlines()
    header_at = next((i for i, line in enumerate(lines) if line.split()[:2] == ["NR", "AXISPOS"]),
                     None)
    if header_at is None:
        raise LineError(path, "no 'NR AXISPOS ...' header line", field="AXISPOS")
    header = lines[header_at].split()
    if len(header) < 3:
        raise LineError(path, "needs a column for the axis", header_at + 1)
    rows = []
    for line_number in range(header_at + 2, len(lines) + 1):
        fields = lines[line_number - 1].split()
        if not fields or re.match(r"\[END\]", fields[0]):
            break
        if len(fields) != len(header):
            raise LineError(path, f"{len(fields)} fields, the header has {len(header)}",
                            line_number)
        rows.append([number(v, path, line_number, name) for v, name in zip(fields, header)])
    if not 2 <= len(rows) <= MAX_POINTS:
        raise LineError(path, f"needs 2 to {MAX_POINTS} entries, found {len(rows)}",
                        header_at + 2)
    values = np.array(rows)
    columns = dict(zip(header, values.T))
    forward_um = columns[header[2]] * UM_PER_MM
    reverse_um = columns["BACKLASH"] * UM_PER_MM if "BACKLASH" in columns else forward_um
    position_mm = columns["AXISPOS"]
    for index in np.flatnonzero(np.diff(position_mm) <= 0):
        raise LineError(path, "AXISPOS must increase", header_at + index + 3, "AXISPOS")
    return CompTable(position_mm, forward_um, reverse_um, "file")


CONTROLLER = Controller(NAME, write, read, MAX_POINTS, EQUIDISTANT, DEFAULT_AXIS_ID, SIGN, LOAD,
                        axis_id_pattern=AXIS_ID,
                        companions=companions,
                        out_note="the .COM; its .CMA goes beside it", axis_note=DEFAULT_AXIS_ID,
                        suffix=".COM")
