"""The files of a circular test (ISO 230-4, case format 1.2): the axis.toml of a machine of
two axes (``[circular]`` and one ``[axes.NAME]`` per axis) and ``circular.csv``.

Every rule is checked as for the one-axis files (:mod:`feedaxis.case`): a broken file raises
one :class:`~feedaxis.case.CaseError` naming the file, the row and the column.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .case import (TABLES, CaseError, _first_bad, _read_csv, _unknown_key_message,
                   _value_problem, axis_of, check_name, check_table, checked_run,
                   read_axis_values)
from .errors import shown_value, toml_key_line

CIRCULAR_FILE = "circular.csv"
CIRCULAR_COLUMNS = {"angle_deg": True, "deviation_um": True, "direction": True, "run": False,
                    "time_s": False}
CIRCULAR_KEYS = ("axes", "radius_mm", "feed_mm_min", "center_mm")
AXIS_NAME = re.compile(r"[A-Za-z0-9]{1,8}")


@dataclass(frozen=True)
class CircularTest:
    """``[circular]`` of axis.toml: the plane's two axes (angle 0° along + the first, 90°
    along + the second), the nominal radius, the programmed feed, the centre (machine
    coordinates, in the order of ``axes``)."""

    axes: tuple
    radius_mm: float
    feed_mm_min: float
    center_mm: tuple


@dataclass(frozen=True)
class Machine:
    """The axis.toml of a circular case: its name, ``[circular]`` and one :class:`Axis`
    per ``[axes.NAME]`` (in the order of ``circular.axes``)."""

    name: str
    circular: CircularTest
    axes: dict

    def axis(self, name):
        return self.axes[name]


@dataclass(frozen=True)
class CircularSamples:
    """circular.csv as arrays: nominal angle (deg), radial deviation (µm, + outside), the
    direction (+1 counter-clockwise), and the optional run and time."""

    angle_deg: np.ndarray
    deviation_um: np.ndarray
    direction: np.ndarray
    run: np.ndarray | None = None
    time_s: np.ndarray | None = None

    @property
    def size(self):
        return self.angle_deg.size

    @property
    def bidirectional(self):
        """True when both directions were measured."""
        return {-1.0, 1.0} <= set(np.unique(self.direction))


def read_machine(path):
    """Read the axis.toml of a circular case: ``name``, ``[circular]`` and one
    ``[axes.NAME]`` (``screw``, ``motor``, ``servo``) per axis of ``[circular] axes``."""
    path = Path(path)
    text, data = read_axis_values(path)
    for key, value in data.items():
        if key == "name":
            check_name(path, text, value)
        elif key not in ("circular", "axes") or not isinstance(value, dict):
            raise CaseError(path, _unknown_key_message(key, ["name", "[circular]",
                                                             "[axes.NAME]"])
                            + ("; a circular case describes each axis under [axes.NAME]"
                               if key in TABLES else ""), toml_key_line(text, key), key)
    if "circular" not in data:
        raise CaseError(path, "a circular case needs [circular] (axes, radius_mm, "
                              "feed_mm_min, center_mm)", column="circular")
    circular = _check_circular(path, text, data["circular"])
    given = data.get("axes", {})
    for name in given:
        if name not in circular.axes:
            raise CaseError(path, f"[axes.{name}] is not one of [circular] axes "
                                  f"({', '.join(circular.axes)})",
                            toml_key_line(text, f"axes.{name}"), f"axes.{name}")
    axes = {name: _machine_axis(path, text, name, given.get(name, {}))
            for name in circular.axes}
    return Machine(data.get("name", ""), circular, axes)


def _machine_axis(path, text, name, values):
    """The :class:`Axis` of ``[axes.NAME]``: ``screw``, ``motor``, ``servo`` with the keys
    and limits of a one-axis case."""
    prefix = f"axes.{name}"
    if not isinstance(values, dict):
        raise CaseError(path, "must be a table ([axes.NAME.screw], ...)",
                        toml_key_line(text, name, "axes"), prefix)
    tables = {}
    for key, value in values.items():
        if key not in TABLES or not isinstance(value, dict):
            raise CaseError(path, _unknown_key_message(key, ["[screw]", "[motor]", "[servo]"]),
                            toml_key_line(text, key, prefix) or toml_key_line(
                                text, f"{prefix}.{key}"), f"{prefix}.{key}")
        tables[key] = check_table(path, text, key, value, prefix)
    return axis_of(path, text, name, tables, prefix)


def _check_circular(path, text, values):
    """``[circular]``: two distinct axis names, radius > 0, feed > 0, a centre per axis."""
    def fail(key, message):
        raise CaseError(path, message, toml_key_line(text, key, "circular")
                        or toml_key_line(text, "circular"), f"circular.{key}")

    for key in values:
        if key not in CIRCULAR_KEYS:
            fail(key, _unknown_key_message(key, list(CIRCULAR_KEYS)))
    for key in CIRCULAR_KEYS:
        if key not in values:
            fail(key, f"[circular] {key} is required")
    axes = values["axes"]
    if (not isinstance(axes, list) or len(axes) != 2
            or not all(isinstance(a, str) and AXIS_NAME.fullmatch(a) for a in axes)):
        fail("axes", "must be two axis names of 1 to 8 letters or digits, e.g. "
                     f'["X", "Y"], got {shown_value(axes)}')
    if axes[0] == axes[1]:
        fail("axes", f"the two axes must differ, got {axes[0]!r} twice")
    for key in ("radius_mm", "feed_mm_min"):
        problem = _value_problem("positive", key, values[key])
        if problem:
            fail(key, f"{key} {problem}, got {shown_value(values[key])}")
    center = values["center_mm"]
    if not isinstance(center, list) or len(center) != 2:
        fail("center_mm", f"must be two coordinates (mm), one per axis, got "
                          f"{shown_value(center)}")
    for value in center:
        problem = _value_problem("finite", "center_mm", value)
        if problem:
            fail("center_mm", f"center_mm {problem}, got {shown_value(value)}")
    return CircularTest(tuple(axes), float(values["radius_mm"]), float(values["feed_mm_min"]),
                        tuple(float(v) for v in center))


def read_circular(path):
    """Read circular.csv: angle in [0, 360), deviation, direction ±1, optional run and time.

    The rows of one run and direction cover the circle once in the order taken: each angle
    steps the way of the direction (less than half a turn), at most one turn in all, and
    ``time_s`` increases.
    """
    path = Path(path)
    values, rows = _read_csv(path, CIRCULAR_COLUMNS)
    angle, direction = values["angle_deg"], values["direction"]
    _first_bad(path, angle >= 360.0, rows, "angle_deg",
               "angle_deg must be below 360 (0 <= angle < 360)")
    _first_bad(path, ~np.isin(direction, (-1.0, 1.0)), rows, "direction",
               "direction must be +1 (counter-clockwise) or -1 (clockwise)")
    run = checked_run(path, values, rows)
    time_s = values.get("time_s")  # >= 0: the reader's range
    group = direction * 1e9 + (run if run is not None else 1)
    for key in np.unique(group):
        index = np.flatnonzero(group == key)
        _check_pass(path, rows, index, angle[index], direction[index[0]],
                    None if time_s is None else time_s[index])
    return CircularSamples(angle, values["deviation_um"], direction,
                    run.astype(int) if run is not None else None, time_s)


def _check_pass(path, rows, index, angle_deg, direction, time_s):
    """One run in one direction: steps the direction's way, at most one turn, time rising."""
    steps = np.mod(direction * np.diff(angle_deg), 360.0)
    bad = np.flatnonzero((steps <= 0.0) | (steps >= 180.0))
    if bad.size:
        raise CaseError(path, "the angle must step "
                              f"{'up' if direction > 0 else 'down'} from the previous row of "
                              f"this run and direction ({'+1' if direction > 0 else '-1'}), "
                              "by less than half a turn", rows[index[bad[0] + 1]], "angle_deg")
    turned = np.cumsum(steps)
    over = np.flatnonzero(turned >= 360.0)
    if over.size:
        raise CaseError(path, "this run and direction cover more than one turn; number "
                              "repeated turns with the run column", rows[index[over[0] + 1]],
                        "angle_deg")
    if time_s is not None:
        _first_bad(path, np.diff(time_s) <= 0, [rows[i] for i in index[1:]], "time_s",
                   "time_s must increase within a run and direction")
