"""The wide CSV engineers keep in spreadsheets: one row per target, one column per run and
direction.

Layout: a header row; the first column ``target_mm`` (mm); then one column per run and
approach direction named ``run<N>+`` / ``run<N>-`` (also ``run<N>_up`` / ``run<N>_down``,
any case, spaces ignored), the deviation measured − target in µm. An empty cell is a point
not measured. Lines starting with ``#`` are comments. The separator is ``,``; a file
separated by ``;`` (or tabs) may use a decimal comma, as spreadsheets in many locales save.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..case import PHYSICAL_RANGE
from ..errors import read_text, text_lines
from ..linefile import LineError, number
from . import Measurement

COLUMN = re.compile(r"^run(\d+)(?:_?(up|down)|([+-]))$")


def _separator(header):
    for separator in (";", "\t"):
        if separator in header:
            return separator
    return ","


def _run_column(path, name, line):
    match = COLUMN.match(re.sub(r"\s+", "", name).lower())
    if not match or int(match.group(1)) < 1:
        raise LineError(path, "expected run<N>+ or run<N>- (or run<N>_up / _down)",
                        line, name)
    sign = match.group(3) or ("+" if match.group(2) == "up" else "-")
    return int(match.group(1)), 1.0 if sign == "+" else -1.0


def _cell(path, text, line, column, decimal_comma, quantity):
    """The number in a cell (its ``quantity``'s physical range checked)."""
    text = text.strip()
    return number(text.replace(",", ".") if decimal_comma else text, path, line, column,
                  PHYSICAL_RANGE[quantity])


def read_wide_csv(path):
    """Read a wide CSV into a :class:`~feedaxis.importers.Measurement`."""
    path = Path(path)
    rows = [(number, line) for number, line in
            enumerate(text_lines(read_text(path, "wide CSV")), 1)
            if line.strip() and not line.lstrip().startswith("#")]
    if len(rows) < 2:
        raise LineError(path, "needs a header row and at least one target row")
    header_line, header_text = rows[0]
    separator = _separator(header_text)
    header = [name.strip() for name in header_text.split(separator)]
    if header[0] != "target_mm":
        raise LineError(path, "the first column must be target_mm", header_line,
                        header[0])
    runs = [_run_column(path, name, header_line) for name in header[1:]]
    if not runs:
        raise LineError(path, "no run columns after target_mm", header_line)
    for index, run in enumerate(runs):
        if run in runs[:index]:
            raise LineError(path, "column appears twice", header_line, header[index + 1])
    columns = {"target_mm": [], "error_um": [], "direction": [], "run": []}
    targets = set()
    for line, text in rows[1:]:
        cells = text.split(separator)
        if len(cells) != len(header):
            raise LineError(path, f"{len(cells)} fields, the header has {len(header)}",
                            line)
        target = _cell(path, cells[0], line, "target_mm", separator != ",", "target_mm")
        if target in targets:
            raise LineError(path, "target appears twice", line, "target_mm")
        targets.add(target)
        for (run, sign), name, cell in zip(runs, header[1:], cells[1:]):
            if cell.strip():
                columns["target_mm"].append(target)
                columns["error_um"].append(_cell(path, cell, line, name, separator != ",",
                                                 "error_um"))
                columns["direction"].append(sign)
                columns["run"].append(run)
    if not columns["error_um"]:
        raise LineError(path, "no deviations: every run cell is empty")
    return Measurement(*(np.array(columns[k], dtype=float) for k in columns))
