"""Fanuc pitch-error compensation: parameters 3620-3627 and the incremental values per point.

Points are ``3624`` apart (detection units); point n holds the *increment* of the correction
over the interval ending at it, x(n) = x_ref + (n − ``3620``)·``3624``, so the correction at
a point is the sum of the increments from the reference position (0 there). Values are
multiplied by ``3623``. Farthest points: ``3621`` (− side), ``3622`` (+ side). Bidirectional
(``3605#0`` = 1): the negative-direction table follows from point ``3626`` on, and ``3627``
is its absolute value at the reference position (parameter manual B-63980EN, pitch error
compensation). The correction is added to the motion, so it is −(measured − target), in
detection units of 1 µm. Written in Fanuc's parameter tape format ``N<number> A<axis> P<v>``
with pitch data as ``N<10000 + point> P<v>``.

The points are counted from the reference position, whose machine coordinate is parameter
1240: that is the machine's home, never written here (a tape that set it would move the
machine's reference position). The table therefore needs a point at the reference position,
machine zero by default (``GRID_THROUGH_ZERO``: the table grid is laid through 0 mm); a
tape that carries 1240 (a full parameter dump) is read at that coordinate.
"""
from __future__ import annotations

import re

import numpy as np

from ..errors import InputError
from ..linefile import LineError
from .base import (Controller, check_equidistant, check_points, quantized, reference_index,
                   reference_note)
from .table import CompTable

NAME = "fanuc"
MAX_POINTS = 128  # per direction, between the extremes
EQUIDISTANT = True
GRID_THROUGH_ZERO = True  # the reference position (machine zero) is a table point
REFERENCE_COORDINATE = 1240  # read when present, never written
DEFAULT_AXIS_ID = "1"
AXIS_ID = r"[1-9][0-9]?"  # the controlled axis number of A<axis>
DETECTION_UNIT_UM = 1.0
MAX_VALUE = 127
PITCH_DATA = 10000
BIDIRECTIONAL_BITS = 3605  # bit parameter, written bit 7 .. bit 0; #0 = bidirectional
SIGN = "increment of -(measured - target) per interval, detection units (1 µm) x 3623"
LOAD = ("parameter tape (or MDI): 3605#0 = 1 for bidirectional, 3620-3627, then the pitch "
        "data; power off and on, reference return (G28); point 3620 is the reference position "
        "at 0 mm (parameter 1240 = 0)")
PATTERN = r"^N(\d{1,9})\s*(?:A(\d{1,9}))?\s*P([-+]?\d{1,9})\s*$"  # 9 digits: any parameter
LAST_POINT = 1023  # compensation points are numbered 0 to 1023 (B-63980EN, 3620-3622)


def _magnification(*corrections_um):
    """The smallest 3623 that keeps every increment of each table within ±127."""
    steps = max(float(np.max(np.abs(np.diff(c)), initial=0.0)) for c in corrections_um)
    return max(1, int(np.ceil(steps / DETECTION_UNIT_UM / (MAX_VALUE - 0.5))))


def _increments(correction, reference):
    """Absolute corrections (units, 0 at ``reference``) as increments per interval."""
    absolute = correction - correction[reference]
    return np.diff(absolute)


def write(table, axis_id=DEFAULT_AXIS_ID):
    """The parameter tape of ``table`` for controlled axis ``axis_id``."""
    check_points(table, MAX_POINTS, NAME)
    spacing_mm = check_equidistant(table, NAME)
    j_ref = reference_index(table.position_mm)
    if abs(table.position_mm[j_ref]) > 5e-4:
        raise InputError(f"{NAME} counts its points from the reference position at 0 mm; the "
                         f"nearest table point is at {table.position_mm[j_ref]:g} mm: choose a "
                         "spacing that puts a point at 0 mm", parameter="--spacing-mm")
    forward, reverse = -table.forward_um, -table.reverse_um
    magnification = _magnification(forward, reverse)
    unit = DETECTION_UNIT_UM * magnification
    forward_units, reverse_units = quantized(forward, unit), quantized(reverse, unit)
    reference = max(j_ref, 1)
    lowest = min(reference - j_ref + 1, reference)
    highest = reference + table.size - 1 - j_ref
    parameters = {3620: reference, 3621: lowest, 3622: highest, 3623: magnification,
                  3624: int(round(spacing_mm * 1e3 / DETECTION_UNIT_UM))}
    data = _point_values(lowest, reference, j_ref, _increments(forward_units, j_ref))
    if table.bidirectional:
        start = highest + 1
        parameters.update({BIDIRECTIONAL_BITS: "00000001", 3626: start,
                           3627: int(reverse_units[j_ref] - forward_units[j_ref])})
        data.update(_point_values(start, start + reference - lowest, j_ref,
                                  _increments(reverse_units, j_ref)))
    lines = ["%"] + [f"N{n} A{axis_id} P{v}" for n, v in sorted(parameters.items())]
    lines += [f"N{PITCH_DATA + n} P{v}" for n, v in sorted(data.items())] + ["%"]
    return "\n".join(lines) + "\n"


def _point_values(lowest, reference, j_ref, increments):
    """{point number: increment}: point n ends the interval at table index n − ref + j_ref;
    a point before the table's first index holds 0."""
    values = {}
    for n in range(lowest, reference + increments.size - j_ref + 1):
        k = n - reference + j_ref
        values[n] = int(increments[k - 1]) if k >= 1 else 0
    return values


def _absolute(data, lowest, highest, reference, start_value):
    """Corrections at points lowest − 1 .. highest from the increments, ``start_value`` at
    the reference."""
    numbers = np.arange(lowest - 1, highest + 1)
    values = np.array([data.get(n, 0) for n in numbers], dtype=float)
    cumulative = np.concatenate(([0.0], np.cumsum(values[1:])))
    return cumulative - cumulative[reference - lowest + 1] + start_value


def read(text, path="PITCH.TXT"):
    """The corrections the control applies, as the deviation per direction (µm)."""
    parameters, data, bits = {}, {}, "0"
    for line_number, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if stripped in ("", "%"):
            continue
        match = re.match(PATTERN, stripped)
        if not match:
            raise LineError(path, "expected N<number> [A<axis>] P<value>", line_number)
        number_, value = int(match.group(1)), int(match.group(3))
        if number_ == BIDIRECTIONAL_BITS:
            bits = match.group(3)
        elif number_ >= PITCH_DATA:
            data[number_ - PITCH_DATA] = value
        else:
            parameters[number_] = value
    bidirectional = bits.endswith("1")
    for key in (3620, 3621, 3622, 3623, 3624) + ((3626, 3627) if bidirectional else ()):
        if key not in parameters:
            raise LineError(path, "missing parameter", field=str(key))
    reference, lowest, highest = parameters[3620], parameters[3621], parameters[3622]
    if not lowest <= reference <= highest or parameters[3624] <= 0 or parameters[3623] < 1:
        raise LineError(path, "needs 3621 <= 3620 <= 3622, 3623 >= 1 and 3624 > 0",
                        field="3620")
    last = parameters[3626] + highest - lowest if bidirectional else highest
    if lowest < 0 or last > LAST_POINT or (bidirectional and parameters[3626] <= highest):
        raise LineError(path, f"the points (3621 to 3622, and from 3626 for the negative "
                              f"direction after 3622) must lie within 0 to {LAST_POINT}",
                        field="3622")
    unit = DETECTION_UNIT_UM * parameters[3623]
    position_mm = (parameters.get(REFERENCE_COORDINATE, 0)
                   + parameters[3624] * np.arange(lowest - 1 - reference, highest - reference + 1)
                   ) * DETECTION_UNIT_UM / 1e3
    forward = _absolute(data, lowest, highest, reference, 0.0) * unit
    reverse = forward
    if bidirectional:
        start = parameters[3626]
        reverse = _absolute(data, start, start + highest - lowest, start + reference - lowest,
                            parameters[3627]) * unit
    return CompTable(position_mm, -forward, -reverse, "file")


CONTROLLER = Controller(NAME, write, read, MAX_POINTS, EQUIDISTANT, DEFAULT_AXIS_ID, SIGN, LOAD,
                        axis_id_pattern=AXIS_ID,
                        grid_through_zero=GRID_THROUGH_ZERO,
                        notes=lambda table: [reference_note(table)],
                        quantum_um=DETECTION_UNIT_UM, axis_note=f"axis {DEFAULT_AXIS_ID}")
