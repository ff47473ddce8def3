"""A drive's trace export (CSV) read through a column map into tracking.csv's columns.

Drives export their traces with their own column names and units (``Pos_cmd [µm]``,
``n_act [rpm]``, ``I_q [A]``). ``--map TARGET=SOURCE[*SCALE]`` names, for each column of
tracking.csv, the export's column and the factor to its unit: ``time_s``, ``reference_mm``,
``actual_mm`` (required; ``sample`` with ``--sample-time-s`` instead of ``time_s``),
``control_V`` (the controller output: a current or torque setpoint taken as the loop's
"volt", with ``[servo] force_constant_N_per_V`` in newtons per that unit) and
``disturbance_N``. A target the case format has no column for, a column the export does not
have, a factor that is not a number, or a cell that is not a number is refused, naming it;
the export's columns left unmapped are reported, not silently lost.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import InputError, read_text

TARGETS = ("time_s", "sample", "reference_mm", "actual_mm", "control_V", "disturbance_N")
REQUIRED = ("reference_mm", "actual_mm")


def parse_map(entries):
    """{target: (source column, factor)} from ``TARGET=SOURCE[*SCALE]`` entries."""
    mapping = {}
    for entry in entries:
        target, separator, source = entry.partition("=")
        target, source = target.strip(), source.strip()
        if not separator or not source:
            raise InputError("expected TARGET=SOURCE[*SCALE], e.g. actual_mm=Pos_act*0.001",
                             parameter=f"--map {entry}")
        if target not in TARGETS:
            raise InputError(f"tracking.csv has no column '{target}'; a drive trace maps to: "
                             f"{', '.join(TARGETS)}", parameter=f"--map {entry}")
        column, _, scale = source.rpartition("*") if "*" in source else (source, "", "1")
        try:
            factor = float(scale)
        except ValueError:
            factor = math.nan
        if not math.isfinite(factor) or factor == 0.0:
            raise InputError(f"the factor '{scale}' is not a finite, non-zero number",
                             parameter=f"--map {entry}")
        mapping[target] = (column.strip(), factor)
    return mapping


def _delimiter(header):
    return max((";", "\t", ","), key=header.count)


def read_drive_trace(path, mapping, sample_time_s=None):
    """(tracking.csv columns, {dropped column: why}) of the export at ``path``."""
    path = Path(path)
    lines = [line for line in read_text(path, "drive trace").splitlines()
             if line.strip() and not line.lstrip().startswith("#")]
    if len(lines) < 2:
        raise InputError("a header row and at least one data row are needed", path=path)
    delimiter = _delimiter(lines[0])
    header = [cell.strip().strip('"') for cell in lines[0].split(delimiter)]
    missing = [t for t in REQUIRED if t not in mapping]
    if "time_s" not in mapping and not ("sample" in mapping and sample_time_s):
        missing.append("time_s (or sample with --sample-time-s)")
    if missing:
        raise InputError(f"--map gives no column for {', '.join(missing)}", path=path)
    for target, (column, _) in mapping.items():
        if column not in header:
            raise InputError(f"the export has no column '{column}' (for {target}); its columns: "
                             f"{', '.join(header)}", path=path, column=column)
    columns = {}
    for target, (column, factor) in mapping.items():
        index = header.index(column)
        values = np.empty(len(lines) - 1)
        for row, line in enumerate(lines[1:], start=2):
            cells = line.split(delimiter)
            text = cells[index].strip().strip('"') if index < len(cells) else ""
            if delimiter != "," and "," in text and "." not in text:
                text = text.replace(",", ".")  # decimal comma
            try:
                values[row - 2] = float(text)
            except ValueError:
                raise InputError(f"'{text}' is not a number", path=path, row=row,
                                 column=column) from None
        columns[target] = values * factor
    sample = columns.pop("sample", None)
    if "time_s" not in columns:
        columns["time_s"] = (sample - sample[0]) * sample_time_s
    order = ("time_s", "reference_mm", "actual_mm", "disturbance_N", "control_V")
    used = {column for column, _ in mapping.values()}
    dropped = {column: "not mapped (--map TARGET=SOURCE to keep it)"
               for column in header if column not in used}
    return {name: columns[name] for name in order if name in columns}, dropped
