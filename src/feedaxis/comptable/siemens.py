"""Siemens Sinumerik 840D leadscrew / encoder error compensation (LEC/EEC), ``%_N_AX_EEC_INI``.

Equidistant points from ``$AA_ENC_COMP_MIN`` to ``_MAX`` every ``_STEP`` (mm), the value of
point i in ``$AA_ENC_COMP[0,i,AX]`` (mm), linear between points. The manual (function manual
K3): "a positive compensation value causes the corresponding machine axis to move in the
negative direction", so value = measured − target; the value at the reference point should
be 0 (no jump when compensation switches on after referencing). The direction-dependent part
goes into two sag/cross-error (CEC) tables of the same axis, ``$AN_CEC_DIRECTION`` = 1 and −1,
in ``%_N_NC_CEC_INI``; their value is a correction added to the setpoint (−deviation).
"""
from __future__ import annotations

import numpy as np

from ..linefile import LineError, number
from .base import (UM_PER_MM, Controller, assignments, check_equidistant, check_points,
                   reference_index, reference_note, require)
from .table import CompTable

NAME = "siemens"
MAX_POINTS = None  # set by MD38000 $MA_MM_ENC_COMP_MAX_POINTS; the output says how many
EQUIDISTANT = True
DEFAULT_AXIS_ID = "X1"
AXIS_ID = r"[A-Za-z_][A-Za-z0-9_]{0,15}"  # a machine axis name (X1, AX1)
SIGN = ("EEC value = measured - target (mm), 0 at the reference point; CEC (direction part) "
        "value = -(deviation) (mm)")
LOAD = ("MD38000 $MA_MM_ENC_COMP_MAX_POINTS >= points, MD32700 ENC_COMP_ENABLE[0] = 1 "
        "(and MD18342 / MD32710 CEC_ENABLE for the CEC part); load the INI file, power on, "
        "reference the axis")
PATTERN = r"^(\$A[AN]_[A-Z_]+\[[^\]]*\])\s*=\s*(\S+)"
CEC_TABLES = ((0, 1.0), (1, -1.0))


def _mm(value_um):
    return f"{value_um / UM_PER_MM:.6f}"


def _grid_lines(prefix, suffix, table, spacing_mm):
    return [f"{prefix}_STEP{suffix}={spacing_mm:.6f}",
            f"{prefix}_MIN{suffix}={table.position_mm[0]:.6f}",
            f"{prefix}_MAX{suffix}={table.position_mm[-1]:.6f}"]


def write(table, axis_id=DEFAULT_AXIS_ID):
    """The EEC (and, for a direction-dependent table, CEC) INI text for machine axis
    ``axis_id``."""
    check_points(table, MAX_POINTS, NAME)
    spacing_mm = check_equidistant(table, NAME)
    mean_um = (table.forward_um + table.reverse_um) / 2
    mean_um = mean_um - mean_um[reference_index(table.position_mm)]
    lines = ["%_N_AX_EEC_INI", "CHANDATA(1)"]
    lines += [f"$AA_ENC_COMP[0,{i},{axis_id}]={_mm(v)}" for i, v in enumerate(mean_um)]
    lines += _grid_lines("$AA_ENC_COMP", f"[0,{axis_id}]", table, spacing_mm)
    lines += [f"$AA_ENC_COMP_IS_MODULO[0,{axis_id}]=0", "M17"]
    if table.bidirectional:
        half_um = (table.forward_um - table.reverse_um) / 2
        lines += ["%_N_NC_CEC_INI", "CHANDATA(1)"]
        for index, sign in CEC_TABLES:
            lines += [f"$AN_CEC[{index},{i}]={_mm(-sign * v)}" for i, v in enumerate(half_um)]
            lines += [f"$AN_CEC_INPUT_AXIS[{index}]={axis_id}",
                      f"$AN_CEC_OUTPUT_AXIS[{index}]={axis_id}",
                      *_grid_lines("$AN_CEC", f"[{index}]", table, spacing_mm),
                      f"$AN_CEC_DIRECTION[{index}]={int(sign)}",
                      f"$AN_CEC_IS_MODULO[{index}]=0"]
        lines.append("M17")
    return "\n".join(lines) + "\n"


def _grid(found, prefix, suffix, path):
    values = {}
    for name in ("STEP", "MIN", "MAX"):
        key = f"{prefix}_{name}{suffix}"
        text, line = require(found, key, path)
        values[name] = (number(text, path, line, key), line, key)
    step, line, key = values["STEP"]
    if step <= 0:
        raise LineError(path, "must be > 0", line, key)
    (low, _, _), (high, high_line, high_key) = values["MIN"], values["MAX"]
    if not high > low:
        raise LineError(path, f"must be above {prefix}_MIN{suffix} ({low:g}), got {high:g}",
                        high_line, high_key)
    count = (high - low) / step + 1
    if count > len(found):  # each point needs its value: the file cannot hold them
        raise LineError(path, f"MIN {low:g} to MAX {high:g} every {step:g} mm asks for "
                              f"{count:.3g} points; the file holds {len(found)} values",
                        line, key)
    return low + step * np.arange(int(round(count)))


def _values(found, key_of, count, path):
    keys = [key_of(i) for i in range(count)]
    return np.array([number(require(found, k, path)[0], path, found[k][1], k) for k in keys])


def read(text, path="AX_EEC.INI"):
    """The compensation the control applies: EEC values plus, per direction, its CEC table."""
    found = assignments(text, path, PATTERN)
    axes = {key.split(",")[-1].rstrip("]") for key in found if key.startswith("$AA_ENC_COMP[")}
    if len(axes) != 1:
        raise LineError(path, "expected the $AA_ENC_COMP values of one axis",
                        field="$AA_ENC_COMP")
    axis_id = axes.pop()
    position_mm = _grid(found, "$AA_ENC_COMP", f"[0,{axis_id}]", path)
    mean_um = _values(found, lambda i: f"$AA_ENC_COMP[0,{i},{axis_id}]", position_mm.size,
                      path) * UM_PER_MM
    direction_um = {1.0: np.zeros(position_mm.size), -1.0: np.zeros(position_mm.size)}
    for index, _ in CEC_TABLES:
        if f"$AN_CEC_DIRECTION[{index}]" not in found:
            continue
        key = f"$AN_CEC_DIRECTION[{index}]"
        sign = number(found[key][0], path, found[key][1], key)
        cec_mm = _grid(found, "$AN_CEC", f"[{index}]", path)
        correction_um = _values(found, lambda i: f"$AN_CEC[{index},{i}]", cec_mm.size,
                                path) * UM_PER_MM
        direction_um[sign] = -np.interp(position_mm, cec_mm, correction_um)
    return CompTable(position_mm, mean_um + direction_um[1.0], mean_um + direction_um[-1.0],
                     "file")


def notes(table):
    """The reference point and the machine data the table needs."""
    return [reference_note(table),
            f"needs MD38000 $MA_MM_ENC_COMP_MAX_POINTS >= {table.size}"
            + (f" and MD18342 $MN_MM_CEC_MAX_POINTS[0] and [1] >= {table.size}"
               if table.bidirectional else "")]


CONTROLLER = Controller(NAME, write, read, MAX_POINTS, EQUIDISTANT, DEFAULT_AXIS_ID, SIGN, LOAD,
                        axis_id_pattern=AXIS_ID,
                        notes=notes, axis_note=DEFAULT_AXIS_ID)
