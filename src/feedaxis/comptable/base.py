"""What every controller format shares: assignments read back with the line they came from,
the point limit, the equidistant grid, the reference point and integer units."""
from __future__ import annotations

import re

import numpy as np

from ..errors import InputError
from ..linefile import LineError

UM_PER_MM = 1000.0


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
