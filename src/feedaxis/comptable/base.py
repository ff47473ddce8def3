"""What every controller format shares: the :class:`Controller` each controller's module
defines, assignments read back with the line they came from, the point limit, the
equidistant grid, the reference point and integer units."""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import InputError
from ..linefile import LineError

UM_PER_MM = 1000.0


def _no_companions(out_path, axis_id):
    return {}


def _no_notes(table):
    return []


@dataclass(frozen=True)
class Controller:
    """One CNC controller's compensation file, as its module defines it (``CONTROLLER``) and
    :data:`feedaxis.comptable.CONTROLLERS` registers it.

    ``write(table, axis_id) -> text`` and ``read(text) -> CompTable`` (the table as the
    controller applies it); ``max_points`` (None: set on the machine), ``equidistant``
    (points on an even grid), ``grid_through_zero`` (the reference position at 0 mm is a
    table point), ``sign`` and ``load`` (the sign convention and how to load the file, for
    the output), ``companions(out_path, axis_id) -> {path: text}`` (files written beside
    it), ``notes(table) -> [str]`` (what the controller needs of the machine for this
    table), ``quantum_um`` (the value's resolution, µm; 0 when finer than a nanometre), and
    for the command line's help ``out_note`` (what ``--out`` names) and ``axis_note`` (the
    default axis name as the manual writes it); ``axis_id_pattern``, the regular expression
    an ``--axis-id`` must match whole (what the file holds there: no newline, no word more); ``suffix``
    the file ending the control finds its table by ("" when any name serves).
    """

    name: str
    write: Callable
    read: Callable
    max_points: int | None
    equidistant: bool
    default_axis_id: str
    sign: str
    load: str
    grid_through_zero: bool = False
    companions: Callable = _no_companions
    notes: Callable = _no_notes
    quantum_um: float = 0.0
    out_note: str = ""
    axis_note: str = ""
    suffix: str = ""
    axis_id_pattern: str = r"[A-Za-z0-9_]{1,16}"

    @property
    def module(self):
        """The name of the module defining it."""
        return self.write.__module__.rsplit(".", 1)[-1]


def reference_note(table):
    """The note of a controller that references its values to the table point nearest 0 mm."""
    return (f"values are relative to the table point nearest 0 mm "
            f"({table.position_mm[reference_index(table.position_mm)]:g} mm), where "
            "the control references; the figures are unchanged by that offset")


def assignments(text, path, pattern):
    """{key: (value text, line)} of the lines matching ``pattern`` (groups: key, value)."""
    found = {}
    for line_number, line in enumerate(text.splitlines(), 1):
        match = re.match(pattern, line.strip())
        if match:
            found[match.group(1)] = (match.group(2).strip(), line_number)
    return found


def require(found, key, path):
    """The (value text, line) of ``key`` in ``found``, else a :class:`LineError`."""
    if key not in found:
        raise LineError(path, "missing", field=key)
    return found[key]


def check_points(table, maximum, controller):
    """Raise when ``table`` has more points than ``controller`` accepts."""
    if maximum and table.size > maximum:
        raise InputError(f"{table.size} table points; {controller} accepts at most {maximum}: "
                         "choose a larger spacing", parameter="--spacing-mm")


def check_equidistant(table, controller):
    """The spacing (mm) of an equidistant ``table``; raise when it is not equidistant."""
    steps = np.diff(table.position_mm)
    if steps.size == 0 or np.ptp(steps) > 1e-6:
        raise InputError(f"{controller} needs equidistant table points; give --spacing-mm",
                         parameter="--spacing-mm")
    return float(np.round(np.mean(steps), 6))


def reference_index(position_mm):
    """The table point the controller references to: the one nearest machine zero."""
    return int(np.argmin(np.abs(position_mm)))


def quantized(values, unit):
    """``values`` rounded to whole multiples of ``unit`` (as integers)."""
    return np.round(np.asarray(values, dtype=float) / unit).astype(int)
