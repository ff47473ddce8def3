"""LinuxCNC joint ``COMP_FILE`` of ``COMP_FILE_TYPE = 1``.

One line per point, ``nominal forward_trim reverse_trim`` in machine units (mm), nominals
strictly increasing, nothing else: the loader stops at the first line that is not three
numbers. Trims are added to the commanded position when moving in + / −, interpolated
linearly between lines, so trim = −(deviation) (docs: config/ini-config, COMP_FILE).
"""
from __future__ import annotations

import numpy as np

from ..linefile import LineError
from .base import Controller, UM_PER_MM, check_points
from .table import CompTable

NAME = "linuxcnc"
MAX_POINTS = 256  # EMCMOT_COMP_SIZE
EQUIDISTANT = False
DEFAULT_AXIS_ID = "0"
AXIS_ID = r"[0-9]{1,2}"  # the joint number (not written: the INI names it)
SIGN = "trim = -(measured - target), mm, added to the commanded position"
LOAD = ("[JOINT_n] COMP_FILE = <file>, COMP_FILE_TYPE = 1 in the INI; BACKLASH is then "
        "ignored (the reverse column carries it)")


def write(table, axis_id=DEFAULT_AXIS_ID):
    """The COMP_FILE text of ``table`` (``axis_id`` is not written: the INI names the joint)."""
    check_points(table, MAX_POINTS, NAME)
    return "".join(f"{x:.6f} {-f / UM_PER_MM:.7f} {-r / UM_PER_MM:.7f}\n"
                   for x, f, r in zip(table.position_mm, table.forward_um, table.reverse_um))


def read(text, path="COMP_FILE"):
    """The table LinuxCNC loads from ``text``: lines of three numbers up to the first that is
    not; raise when fewer than two, not increasing or more than 256."""
    rows = []
    for line_number, line in enumerate(text.splitlines(), 1):
        fields = line.split()
        try:
            rows.append([float(v) for v in fields] if len(fields) == 3 else None)
        except ValueError:
            rows.append(None)
        if rows[-1] is None:
            rows.pop()
            break
    if len(rows) < 2:
        raise LineError(path, "needs at least two lines of 'nominal forward reverse'",
                        len(rows) + 1)
    if len(rows) > MAX_POINTS:
        raise LineError(path, f"more than {MAX_POINTS} lines", MAX_POINTS + 1)
    values = np.array(rows)
    for index in np.flatnonzero(np.diff(values[:, 0]) <= 0):
        raise LineError(path, "nominals must increase strictly", index + 2, "nominal")
    bad = np.argwhere(~np.isfinite(values))
    if bad.size:
        raise LineError(path, "must be finite", bad[0][0] + 1,
                        ("nominal", "forward", "reverse")[bad[0][1]])
    return CompTable(values[:, 0], -values[:, 1] * UM_PER_MM, -values[:, 2] * UM_PER_MM,
                     "file")


CONTROLLER = Controller(NAME, write, read, MAX_POINTS, EQUIDISTANT, DEFAULT_AXIS_ID, SIGN, LOAD,
                        axis_id_pattern=AXIS_ID)
