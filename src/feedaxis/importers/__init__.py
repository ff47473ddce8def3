"""Measurement files of other tools turned into a case folder (case format 1.2).

Readers return a :class:`Measurement`; :func:`import_case` writes it with the axis of an
``axis.toml`` through :func:`feedaxis.case.write_case` (atomically: the whole folder or
nothing). Formats: Renishaw ``.rtl`` (:mod:`.rtl`) and the wide CSV of spreadsheets
(:mod:`.wide_csv`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..case import CaseError, read_axis, read_axis_values, read_case, write_case
from ..errors import InputError, check_writable_target


@dataclass(frozen=True)
class Measurement:
    """Deviations (µm) at targets (mm), approach direction ±1 and run (cycle) number;
    ``name`` the axis name the file gives, ``dropped`` what the case format cannot hold,
    ``ambient_C`` the air and ``material_C`` the machine temperature at each sample (°C),
    ``expansion_per_K`` the expansion coefficient the laser software used (1/K), when the
    file gives them."""

    target_mm: np.ndarray
    error_um: np.ndarray
    direction: np.ndarray
    run: np.ndarray
    name: str = ""
    dropped: dict = field(default_factory=dict)
    ambient_C: np.ndarray | None = None
    material_C: np.ndarray | None = None
    expansion_per_K: float | None = None

    def columns(self):
        """positioning.csv columns."""
        columns = {"target_mm": self.target_mm, "error_um": self.error_um,
                   "direction": self.direction, "run": self.run}
        temperatures = {"ambient_C": self.ambient_C, "material_C": self.material_C}
        return {**columns, **{k: v for k, v in temperatures.items() if v is not None}}


def read_measurement(path, columns=None):
    """Read ``path`` by its extension: ``.rtl`` or ``.csv`` (``columns``: the CSV's column
    map, :func:`.wide_csv.column_map`)."""
    from . import rtl, wide_csv

    path = Path(path)
    readers = {".rtl": rtl.read_rtl, ".csv": wide_csv.read_wide_csv}
    if not path.is_file():
        raise InputError("file not found", path=path)
    reader = readers.get(path.suffix.lower())
    if reader is None:
        raise InputError(f"unknown format '{path.suffix}'; known: .rtl (Renishaw), .csv "
                         "(wide: target_mm, then one column per run and direction)", path=path)
    if columns is None:
        return reader(path)
    if reader is not wide_csv.read_wide_csv:
        raise InputError("--columns maps the columns of a .csv export; a .rtl has none",
                         path=path)
    return reader(path, columns)


def import_drive_trace(path, axis_path, out, mapping, sample_time_s=None):
    """Read a drive's trace export ``path`` through ``mapping`` ({target: (column, factor)},
    :func:`.drive_trace.parse_map`), write case folder ``out`` (axis.toml of ``axis_path``,
    which needs its ``[servo]`` table, and tracking.csv). Returns (folder, columns,
    dropped)."""
    from ..measurement.tracking import Tracking
    from .drive_trace import read_drive_trace

    axis_file = _axis_file(axis_path, out)
    if not read_axis(axis_file).servo:
        raise InputError("a drive trace needs the [servo] table in axis.toml (the controller "
                         "as set in the drive)", path=axis_file, column="servo")
    columns, dropped = read_drive_trace(path, mapping, sample_time_s)
    _, axis_values = read_axis_values(axis_file)
    folder = write_case(out, axis_values, check=lambda staged: _check_case(path, staged),
                        **{Tracking.kind: columns})
    return folder, columns, dropped


def _axis_file(axis_path, out):
    """axis.toml of ``axis_path`` (a file or a case folder), checked; ``out`` must be new."""
    axis_path = Path(axis_path)
    axis_file = axis_path / "axis.toml" if axis_path.is_dir() else axis_path
    read_axis(axis_file)
    if Path(out).exists():
        raise InputError("already exists; choose a new case folder", path=out)
    check_writable_target(out, "folder")
    return axis_file


def import_case(path, axis_path, out, columns=None):
    """Read ``path``, write case folder ``out`` with the axis of ``axis_path``.

    The case's name is axis.toml's, else the file's. The case is read back as every command
    reads it before it is published, so nothing is written that would then be refused.
    Returns (folder, measurement, dropped): {field: value} of what the case does not hold.
    """
    axis_file = _axis_file(axis_path, out)
    axis = read_axis(axis_file)
    measurement = read_measurement(path, columns)
    _check_travel(path, measurement, axis)
    _, axis_values = read_axis_values(axis_file)
    dropped = dict(measurement.dropped)
    _take_expansion(measurement, axis_values, dropped)
    if measurement.name:
        if axis_values.get("name"):
            dropped["axis name"] = f"{measurement.name} (axis.toml names the case)"
        else:
            axis_values["name"] = measurement.name
    folder = write_case(out, axis_values, positioning=measurement.columns(),
                        check=lambda staged: _check_case(path, staged))
    return folder, measurement, dropped


def _take_expansion(measurement, axis_values, dropped):
    """Put the file's expansion coefficient into ``[screw] expansion_per_K`` unless axis.toml
    sets it (then the file's value is listed as dropped when it differs)."""
    if measurement.expansion_per_K is None:
        return
    screw = axis_values.setdefault("screw", {})
    given = screw.get("expansion_per_K")
    if given is None:
        screw["expansion_per_K"] = measurement.expansion_per_K
    elif not np.isclose(given, measurement.expansion_per_K, rtol=1e-6):
        dropped["ENVIRONMENT.EXP COEFF"] = (f"{measurement.expansion_per_K:g} /K (axis.toml "
                                            f"sets expansion_per_K = {given:g})")


def _check_travel(path, measurement, axis):
    """Raise naming the export when its targets span more than the screw is long."""
    if "length_m" not in axis.screw:
        return
    length_mm = axis.screw["length_m"] * 1e3
    span_mm = float(np.ptp(measurement.target_mm))
    if span_mm > length_mm * (1 + 1e-9):
        raise InputError(f"the targets span {span_mm:g} mm ({measurement.target_mm.min():g} to "
                         f"{measurement.target_mm.max():g}) on a screw {length_mm:g} mm long "
                         "([screw] length_m of the axis)", path=path, column="target_mm")


def _check_case(path, staged):
    """Read the staged case as every command will; a refusal names the export."""
    try:
        read_case(staged)
    except CaseError as error:
        where = f"{Path(error.path).name} row {error.row}" if error.row else error.path.name
        raise InputError(f"the case it makes breaks the case format ({where}, column "
                         f"{error.column}): {error.message}", path=path) from None
