"""Beckhoff TwinCAT CNC (TF5200) leadscrew error compensation, ``kw.ssfk.*``.

A compensation value list (``achskw*.lis``) with a bilateral table: per point the setpoint
and the value in the positive (``pos``) and negative (``neg``) direction, in 0.1 µm
(``kw.ssfk.unit`` = 1, P-COMP-00017; 0 would mean encoder increments).
The manual's worked example: setpoint 19866.7 µm, measured 19856.5 µm in + gives
``pos = -102``; measured 19874.7 µm in − gives ``neg = +80``: value = measured − setpoint.
Positions between points are interpolated linearly, the end values hold beyond.
"""
from __future__ import annotations

import numpy as np

from ..linefile import LineError, number
from .base import Controller, assignments, check_equidistant, check_points, quantized, require
from .table import CompTable

NAME = "beckhoff"
MAX_POINTS = 1500  # P-COMP-00059 default (kw.ssfk.max_points)
EQUIDISTANT = True
DEFAULT_AXIS_ID = "1"
AXIS_ID = r"[1-9][0-9]{0,2}"  # kopf.log_achs_nr: the logical axis number
UNIT_UM = 0.1
SIGN = "value = measured - setpoint, 0.1 µm (manual's worked example)"
LOAD = ("list file named by achs_kw[i] with achs_kw_log_ax_nr[i] in the start-up "
        "description; lr_param.ssfk = 1 in the axis parameters")
PATTERN = r"^((?:kopf|kw)\.[A-Za-z0-9_.\[\]]+)\s+(\S+)"


def write(table, axis_id=DEFAULT_AXIS_ID):
    """The compensation value list of ``table`` for logical axis number ``axis_id``."""
    check_points(table, MAX_POINTS, NAME)
    spacing_mm = check_equidistant(table, NAME)
    setpoint = quantized(table.position_mm * 1e3, UNIT_UM)
    lines = [f"kopf.log_achs_nr              {axis_id}",
             "kw.ssfk.unit                  1",
             f"kw.ssfk.interval              {int(round(spacing_mm * 1e3 / UNIT_UM))}",
             f"kw.ssfk.kw_startpos           {setpoint[0]}",
             f"kw.ssfk.kw_nr_max             {table.size}",
             "kw.ssfk.bilateral             1",
             "kw.ssfk.modulo                0"]
    for i, (x, pos, neg) in enumerate(zip(setpoint, quantized(table.forward_um, UNIT_UM),
                                          quantized(table.reverse_um, UNIT_UM))):
        lines += [f"kw.ssfk.table[{i}].setpoint     {x}", f"kw.ssfk.table[{i}].pos          {pos}",
                  f"kw.ssfk.table[{i}].neg          {neg}"]
    return "\n".join(lines + ["End of file", ""])


def read(text, path="achskw.lis"):
    """The bilateral table of a ``kw.ssfk`` list (setpoints, pos, neg in 0.1 µm)."""
    found = assignments(text, path, PATTERN)
    unit, line = require(found, "kw.ssfk.unit", path)
    if unit != "1":
        raise LineError(path, "only metric values (1: 0.1 µm) are read; 0 means encoder "
                              "increments", line, "kw.ssfk.unit")
    count = int(number(require(found, "kw.ssfk.kw_nr_max", path)[0], path,
                       found["kw.ssfk.kw_nr_max"][1], "kw.ssfk.kw_nr_max"))
    if not 2 <= count <= MAX_POINTS:
        raise LineError(path, f"must be 2 to {MAX_POINTS}", found["kw.ssfk.kw_nr_max"][1],
                        "kw.ssfk.kw_nr_max")
    columns = {}
    for name in ("setpoint", "pos", "neg"):
        keys = [f"kw.ssfk.table[{i}].{name}" for i in range(count)]
        columns[name] = np.array([number(require(found, k, path)[0], path, found[k][1], k)
                                  for k in keys])
    setpoint_mm = columns["setpoint"] * UNIT_UM / 1e3
    for index in np.flatnonzero(np.diff(setpoint_mm) <= 0):
        key = f"kw.ssfk.table[{index + 1}].setpoint"
        raise LineError(path, "setpoints must increase", found[key][1], key)
    return CompTable(setpoint_mm, columns["pos"] * UNIT_UM, columns["neg"] * UNIT_UM, "file")


CONTROLLER = Controller(NAME, write, read, MAX_POINTS, EQUIDISTANT, DEFAULT_AXIS_ID, SIGN, LOAD,
                        axis_id_pattern=AXIS_ID,
                        axis_note=f"logical axis number {DEFAULT_AXIS_ID}")
