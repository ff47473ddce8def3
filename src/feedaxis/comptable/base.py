"""What every controller format shares: reading numbers back with the line they came from,
the equidistant grid and the reference point, and the one error for a malformed table."""
from __future__ import annotations

import re

import numpy as np

from ..errors import InputError

UM_PER_MM = 1000.0


class TableFormatError(InputError):
    """A compensation file that does not parse: names the file, line and field."""

    def __init__(self, path, message, line=None, field=None):
        super().__init__(message, path=path, row=line, column=field)
        where = [str(path)] + ([f"line {line}"] if line is not None else []) + \
            ([f"field '{field}'"] if field is not None else [])
        self.args = (f"{', '.join(where)}: {message}",)


def number(text, path, line, field):
    """``text`` as a finite float, else :class:`TableFormatError` naming line and field."""
    try:
        value = float(text)
    except ValueError:
        raise TableFormatError(path, f"not a number: {text!r}", line, field) from None
    if not np.isfinite(value):
        raise TableFormatError(path, f"must be finite, got {text!r}", line, field)
    return value


def assignments(text, path, pattern):
    """{key: (value text, line)} of the lines matching ``pattern`` (groups: key, value)."""
    found = {}
    for line_number, line in enumerate(text.splitlines(), 1):
        match = re.match(pattern, line.strip())
        if match:
            found[match.group(1)] = (match.group(2).strip(), line_number)
    return found


def require(found, key, path):
    """The (value text, line) of ``key`` in ``found``, else a :class:`TableFormatError`."""
    if key not in found:
        raise TableFormatError(path, "missing", field=key)
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
