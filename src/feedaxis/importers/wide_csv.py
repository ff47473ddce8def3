"""The wide CSV engineers keep in spreadsheets: one row per target, one column per run and
direction.

Layout: a header row; the first column the target position: ``target_mm`` or a vendor-style
name with its unit (``Target (mm)``, ``Position [m]``); then one column per run and approach
direction: ``run<N>+`` / ``run<N>-`` (also ``run<N>_up`` / ``run<N>_down``), or vendor-style
``Run 1 Fwd (um)``, ``Run 1 Rev (mm)`` (forward / fwd / up / + and reverse / rev / bwd /
backward / down / −), the deviation measured − target, in µm unless the header names a unit.
Names match in any case, spaces ignored. A layout with other names is mapped by
:func:`column_map` (``feedaxis import --columns``). An empty cell is a point not measured.
Lines starting with ``#`` are comments. The separator is ``,``; a file separated by ``;``
(or tabs) may use a decimal comma, as spreadsheets in many locales save.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..case import PHYSICAL_RANGE
from ..errors import InputError, read_text, text_lines
from ..linefile import LineError, number
from . import Measurement

COLUMN = re.compile(r"^run(\d+)_?(up|down|\+|-|fwd|forward|rev|reverse|bwd|back|backward)$")
UNIT = re.compile(r"^(.*?)[(\[]([^)\]]*)[)\]]$")
TARGET_NAMES = ("target", "position", "nominal", "setpoint", "pos")
PLUS = ("up", "+", "fwd", "forward")
# Unit names in a header -> factor to mm (targets) and to µm (deviations)
TO_MM = {"mm": 1.0, "m": 1e3, "um": 1e-3, "µm": 1e-3, "μm": 1e-3, "in": 25.4}
TO_UM = {"um": 1.0, "µm": 1.0, "μm": 1.0, "nm": 1e-3, "mm": 1e3, "m": 1e6, "in": 25.4e3}
ACCEPTED = ("the first column target_mm or a target with its unit ('Target (mm)'), then one "
            "column per run and direction: run<N>+ / run<N>- (or run<N>_up / _down, or "
            "'Run <N> Fwd (um)' / 'Run <N> Rev (um)'); other layouts: --columns "
            "'HEADER=target:mm,HEADER=run1+:um,...'")


def _separator(header):
    for separator in (";", "\t"):
        if separator in header:
            return separator
    return ","


def _split_unit(path, name, line, units, default):
    """(the name without its unit, lower case and without spaces; the unit's factor)."""
    match = UNIT.match(name.strip())
    bare, unit = (match.group(1), match.group(2).strip()) if match else (name, default)
    if unit.lower() not in units:
        raise LineError(path, f"unknown unit '{unit}'; known: {', '.join(units)}", line, name)
    return re.sub(r"\s+", "", bare).lower(), units[unit.lower()]


def _target_column(path, name, line):
    """The factor (to mm) of the target column ``name``."""
    bare, factor = _split_unit(path, name, line, TO_MM, "mm")
    if bare == "target_mm" or (bare in TARGET_NAMES and UNIT.match(name.strip())):
        return factor
    raise LineError(path, f"the first column must be the target position with its unit; "
                          f"accepted: {ACCEPTED}", line, name)


def _run_column(path, name, line):
    """(run, direction ±1, factor to µm) of a deviation column ``name``."""
    bare, factor = _split_unit(path, name, line, TO_UM, "um")
    match = COLUMN.match(bare)
    if not match or int(match.group(1)) < 1:
        raise LineError(path, f"not a run column; accepted: {ACCEPTED}", line, name)
    return int(match.group(1)), 1.0 if match.group(2) in PLUS else -1.0, factor


def column_map(text):
    """{file header: role header} of ``--columns 'HEADER=target:mm,HEADER=run1+:um,...'``:
    each file column renamed to the role it plays, with its unit (InputError when the map
    cannot be read)."""
    mapping = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        header, equals, role = item.partition("=")
        name, _, unit = role.partition(":")
        if not equals or not header.strip() or not name.strip():
            raise InputError(f"expected HEADER=ROLE[:UNIT], got '{item}' (ROLE: target or "
                             "run<N>+ / run<N>-; UNIT: mm, m, um, nm, in)",
                             parameter="--columns")
        mapping[header.strip()] = f"{name.strip()} ({unit.strip()})" if unit else name.strip()
    return mapping


def _cell(path, text, line, column, decimal_comma, quantity, factor=1.0):
    """The number in a cell times ``factor`` (its ``quantity``'s physical range checked)."""
    text = text.strip()
    value = number(text.replace(",", ".") if decimal_comma else text, path, line, column)
    return number(repr(value * factor), path, line, column, PHYSICAL_RANGE[quantity])


def read_wide_csv(path, columns=None):
    """Read a wide CSV into a :class:`~feedaxis.importers.Measurement`; ``columns`` maps
    the file's headers to the roles above (:func:`column_map`)."""
    path = Path(path)
    rows = [(number, line) for number, line in
            enumerate(text_lines(read_text(path, "wide CSV")), 1)
            if line.strip() and not line.lstrip().startswith("#")]
    if len(rows) < 2:
        raise LineError(path, "needs a header row and at least one target row")
    header_line, header_text = rows[0]
    separator = _separator(header_text)
    header = [name.strip() for name in header_text.split(separator)]
    roles = [(columns or {}).get(name, name) for name in header]
    for name in set(columns or {}) - set(header):
        raise LineError(path, f"--columns names '{name}', which the header does not have",
                        header_line)
    target_factor = _target_column(path, roles[0], header_line)
    runs = [_run_column(path, name, header_line) for name in roles[1:]]
    if not runs:
        raise LineError(path, f"no run columns after the target; accepted: {ACCEPTED}",
                        header_line)
    for index, run in enumerate(runs):
        if run[:2] in [r[:2] for r in runs[:index]]:
            raise LineError(path, "the same run and direction appears twice", header_line,
                            header[index + 1])
    columns = {"target_mm": [], "error_um": [], "direction": [], "run": []}
    targets = set()
    for line, text in rows[1:]:
        cells = text.split(separator)
        if len(cells) != len(header):
            raise LineError(path, f"{len(cells)} fields, the header has {len(header)}",
                            line)
        target = _cell(path, cells[0], line, header[0], separator != ",", "target_mm",
                       target_factor)
        if target in targets:
            raise LineError(path, "target appears twice", line, "target_mm")
        targets.add(target)
        for (run, sign, factor), name, cell in zip(runs, header[1:], cells[1:]):
            if cell.strip():
                columns["target_mm"].append(target)
                columns["error_um"].append(_cell(path, cell, line, name, separator != ",",
                                                 "error_um", factor))
                columns["direction"].append(sign)
                columns["run"].append(run)
    if not columns["error_um"]:
        raise LineError(path, "no deviations: every run cell is empty")
    return Measurement(*(np.array(columns[k], dtype=float) for k in columns))
