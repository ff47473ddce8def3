"""Reading, checking and writing a measurement case, format version 1.2 (docs/case-format.md).

A case is one folder: ``axis.toml`` (required), the file of each kind of measurement it
holds (each kind reads its own: :mod:`feedaxis.kinds`), optionally ``duty.csv``. A kind may
own the axis.toml too (its ``axis_tables``: the circular test's machine of two axes); its
case then holds that kind's file alone. Every rule of the format is checked; a broken file
raises one :class:`CaseError` naming the file, the row (1-based, header = row 1) and the
column. This module holds what every file shares: the axis, the duty, the CSV reader and
writer.
"""
from __future__ import annotations

import errno
import math
import os
import shutil
import tempfile
from contextvars import ContextVar
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import tomli_w

from . import kinds
from .errors import (InputError, finite_float, finite_value, read_text, read_toml,
                     shown_value, toml_key_line)
from .output import staging_prefix, umask_mode, writing
from .physics.geometry import SUPPORTS
from .physics.thermal import Segments

# Set by --follow-links: read case files that are links to files outside their folder.
FOLLOW_LINKS = ContextVar("follow_links", default=False)
AXIS_FILE, DUTY_FILE = "axis.toml", "duty.csv"

SCREW_KEYS = {
    "lead_mm": "positive", "length_m": "positive", "diameter_m": "positive",
    "density_kg_m3": "positive", "specific_heat_J_kgK": "positive",
    "expansion_per_K": "positive", "youngs_modulus_Pa": "positive",
    "nut_length_m": "positive", "bearing_length_m": "positive", "support": "support",
    "fixed_end_mm": "finite",
}
MOTOR_KEYS = {"step_angle_deg": "positive", "error_period_steps": "positive_integer"}
SERVO_KEYS = {
    "controller": "controller", "kp_V_per_mm": "positive", "ki_V_per_mm_s": "non_negative",
    "kd_V_s_per_mm": "non_negative", "ko_per_mm": "non_negative", "e_max_mm": "positive",
    "force_constant_N_per_V": "positive", "loop_step_s": "positive",
    "kp_per_s": "positive", "kv_V_s_per_mm": "positive", "tn_s": "positive",
    "velocity_feedforward": "non_negative",
}
PID_KEYS = ("kp_V_per_mm", "ki_V_per_mm_s", "kd_V_s_per_mm", "ko_per_mm", "e_max_mm")
CASCADE_KEYS = ("kp_per_s", "kv_V_s_per_mm", "tn_s", "velocity_feedforward")
SERVO_REQUIRED = {"pid": ("kp_V_per_mm", "ki_V_per_mm_s", "kd_V_s_per_mm"),
                  "npid": ("kp_V_per_mm", "ki_V_per_mm_s", "kd_V_s_per_mm", "ko_per_mm",
                           "e_max_mm"),
                  "cascade": ("kp_per_s", "kv_V_s_per_mm")}
CONTROLLERS = tuple(SERVO_REQUIRED)
DEFAULT_LOOP_STEP_S = 1e-4
TABLES = {"screw": SCREW_KEYS, "motor": MOTOR_KEYS, "servo": SERVO_KEYS}
# Beyond these no machine axis goes: a value outside is a typing or unit slip, refused
# rather than fitted (a 1e-300 Pa screw or 1e300 um deviations overflow the numerics).
PHYSICAL_RANGE = {
    "lead_mm": (1e-3, 1e3), "length_m": (1e-3, 100.0), "diameter_m": (1e-4, 2.0),
    "density_kg_m3": (100.0, 1e5), "specific_heat_J_kgK": (10.0, 1e5),
    "expansion_per_K": (1e-9, 1e-3), "youngs_modulus_Pa": (1e6, 1e13),
    "nut_length_m": (1e-4, 100.0), "bearing_length_m": (1e-4, 100.0),
    "fixed_end_mm": (-1e5, 1e5), "step_angle_deg": (1e-3, 360.0),
    "error_period_steps": (1, 1e6),
    "target_mm": (-1e5, 1e5), "error_um": (-1e5, 1e5), "time_s": (0.0, 1e9),
    "ambient_C": (-100.0, 200.0), "material_C": (-100.0, 200.0), "start_s": (0.0, 1e9), "duration_s": (0.0, 1e9),
    "feed_mm_min": (0.0, 1e6), "from_mm": (-1e5, 1e5), "to_mm": (-1e5, 1e5),
    "reference_mm": (-1e5, 1e5), "actual_mm": (-1e5, 1e5), "disturbance_N": (-1e7, 1e7),
    "kp_V_per_mm": (1e-9, 1e6), "ki_V_per_mm_s": (0.0, 1e6), "kd_V_s_per_mm": (0.0, 1e6),
    "ko_per_mm": (0.0, 1e3), "e_max_mm": (1e-6, 1e3), "force_constant_N_per_V": (1e-6, 1e7),
    "loop_step_s": (1e-7, 0.01), "kp_per_s": (1e-3, 1e5), "kv_V_s_per_mm": (1e-12, 1e6),
    "tn_s": (1e-6, 1e3), "velocity_feedforward": (0.0, 1.0), "control_V": (-1e4, 1e4),
    "radius_mm": (1e-3, 1e5), "center_mm": (-1e5, 1e5), "deviation_um": (-1e5, 1e5),
    "angle_deg": (0.0, 360.0),
}

# What a column accepts, said when a cell of it is not a number at all
ACCEPTED = {"direction": "+1 or -1", "run": "a whole number >= 1"}
DUTY_COLUMNS = {"start_s": True, "duration_s": True, "feed_mm_min": True, "from_mm": True,
                "to_mm": True, "ambient_C": False}


class CaseError(InputError, ValueError):
    """A case file breaks the format: the message names file, row and column."""

    def __init__(self, path, message, row=None, column=None):
        super().__init__(message, path=path, row=row, column=column)


@dataclass(frozen=True)
class Axis:
    """The axis of ``axis.toml``: free-text name, ``[screw]``, ``[motor]`` and ``[servo]``
    values (``servo`` is empty when the table is absent; ``loop_step_s`` is filled in)."""

    name: str
    screw: dict
    motor: dict = field(default_factory=dict)
    servo: dict = field(default_factory=dict)

    @property
    def lead_mm(self):
        return self.screw["lead_mm"]

    def missing(self, table, keys):
        """The ``[table] key`` names among ``keys`` that this axis lacks."""
        values = {"screw": self.screw, "motor": self.motor, "servo": self.servo}[table]
        return [f"[{table}] {key}" for key in keys if key not in values]


@dataclass(frozen=True)
class Duty:
    """duty.csv: consecutive segments from t = 0 (:class:`~feedaxis.physics.thermal.Segments`,
    columns), with the optional ambient per segment."""

    segments: Segments
    ambient_C: np.ndarray | None = None

    @property
    def end_s(self):
        return self.segments[-1].end_s


@dataclass(frozen=True)
class Case:
    """One measurement case folder: its axis, its ``samples`` by kind of measurement
    ({kind: samples}, as each kind reads its file) and the duty of a thermal test.

    ``case.<kind>`` reads the samples of a registered kind (None when the case holds
    none): a kind's own modules address its samples by its name.
    """

    folder: Path
    axis: Axis
    samples: dict = field(default_factory=dict)
    duty: Duty | None = None

    def __getattr__(self, name):
        if name.startswith("_") or name not in kinds.kinds():
            raise AttributeError(f"'Case' object has no attribute {name!r}")
        return self.__dict__.get("samples", {}).get(name)

    @property
    def name(self):
        return self.axis.name or self.folder.name

    @property
    def is_thermal(self):
        """A thermal case: duty.csv beside time-stamped samples (its kind's reader refuses
        a duty without them)."""
        return self.duty is not None

    def with_samples(self, kind, samples):
        """This case with the samples of ``kind`` replaced by ``samples``."""
        return replace(self, samples={**self.samples, kind: samples})


def read_case(folder):
    """Read and check a case folder; raise :class:`CaseError` on the first broken rule."""
    folder = Path(folder)
    if not folder.is_dir():
        raise CaseError(folder, "not a case folder (expected a folder holding axis.toml)")
    _refuse_outside_links(folder)
    owner = _axis_owner(folder)
    if owner is not None:
        return _read_owned_case(folder, owner)
    axis = read_axis(folder / AXIS_FILE)
    duty = (read_duty(folder / DUTY_FILE, length_mm(axis)) if (folder / DUTY_FILE).exists()
            else None)
    registered = kinds.kinds()
    samples = {}
    for name, cls in registered.items():
        read = cls.read(folder, axis, duty)
        if read is not None:
            samples[name] = read
    if not samples:
        one_axis = [cls.file for cls in registered.values()
                    if not getattr(cls, "axis_tables", ())]
        files = ", ".join(one_axis)
        raise CaseError(folder, f"a case holds {files} or both; neither was found"
                        if len(one_axis) == 2 else
                        f"a case holds one or more of {files}; none was found")
    return Case(folder, axis, samples, duty)


def _axis_owner(folder):
    """The kind whose own tables axis.toml holds (its ``axis_tables``), None for an axis."""
    if not (folder / AXIS_FILE).is_file():
        return None
    tables = set(read_axis_values(folder / AXIS_FILE)[1])
    return next((cls for cls in kinds.kinds().values()
                 if tables & set(getattr(cls, "axis_tables", ()))), None)


def _read_owned_case(folder, owner):
    """A case whose axis.toml ``owner`` (a kind) reads: its file alone."""
    axis = owner.read_axis(folder / AXIS_FILE)
    for cls in kinds.kinds().values():
        if cls is not owner and (folder / cls.file).exists():
            raise CaseError(folder / cls.file, f"a case whose axis.toml has "
                                               f"{', '.join(f'[{t}]' for t in owner.axis_tables)} "
                                               f"holds {owner.file} alone ({cls.file} belongs "
                                               "to a one-axis case)")
    if (folder / DUTY_FILE).exists():
        raise CaseError(folder / DUTY_FILE, f"a case of {owner.file} has no duty.csv")
    samples = owner.read(folder, axis, None)
    if samples is None:
        raise CaseError(folder / owner.file, f"missing: axis.toml has "
                                             f"[{owner.axis_tables[0]}], so the case needs "
                                             f"{owner.file}")
    return Case(folder, axis, {owner.kind: samples})


def length_mm(axis):
    """The screw's length (mm), None when axis.toml does not give it."""
    return axis.screw["length_m"] * 1e3 if "length_m" in axis.screw else None


def case_files():
    """The names of the files a case folder may hold: axis.toml, duty.csv and each
    registered kind's file (positioning.csv, tracking.csv, ...)."""
    return (AXIS_FILE, DUTY_FILE, *(cls.file for cls in kinds.kinds().values()))


def _refuse_outside_links(folder):
    """Refuse a case file that resolves outside its case folder (a symbolic link to a file
    elsewhere), before reading anything of it, unless :data:`FOLLOW_LINKS` is set."""
    if FOLLOW_LINKS.get():
        return
    inside = folder.resolve()
    for name in case_files():
        path = folder / name
        if (path.exists() or path.is_symlink()) and inside not in path.resolve().parents:
            raise CaseError(path, "is a link to a file outside the case folder: not read (a "
                                  "case must hold its own files; copy the file in, or give "
                                  "--follow-links to read it anyway)")


def read_axis(path):
    """Read ``axis.toml``: known snake_case keys with units only, each value checked."""
    path = Path(path)
    text, data = read_axis_values(path)
    tables = {}
    for key, value in data.items():
        if key == "name":
            check_name(path, text, value)
        elif key in TABLES and isinstance(value, dict):
            tables[key] = check_table(path, text, key, value)
        else:
            raise CaseError(path, _unknown_key_message(key, ["name", "[screw]", "[motor]",
                                                             "[servo]"]),
                            toml_key_line(text, key), key)
    if "screw" not in tables or "lead_mm" not in tables["screw"]:
        raise CaseError(path, "[screw] lead_mm is required (axial travel per revolution, > 0)",
                        column="screw.lead_mm")
    return axis_of(path, text, data.get("name", ""), tables)


def axis_of(path, text, name, tables, prefix=""):
    """The :class:`Axis` of checked ``tables`` ([screw], [motor], [servo]; ``prefix`` the
    TOML table they stand under, ``axes.X`` in a machine)."""
    servo = (_check_servo(path, text, tables["servo"], prefix) if "servo" in tables else {})
    return Axis(name, tables.get("screw", {}), tables.get("motor", {}), servo)


def check_name(path, text, value):
    """Refuse a ``name`` that is not a string."""
    if not isinstance(value, str):
        raise CaseError(path, "name must be a string", toml_key_line(text, "name"), "name")


def read_axis_values(path):
    """(text, {key: value}) of the TOML of ``axis.toml`` at ``path``, unchecked; a missing,
    unreadable or malformed file is a :class:`CaseError`."""
    path = Path(path)
    if not path.exists():
        raise CaseError(path, "missing: every case needs axis.toml")
    try:
        return read_toml(path, "case file")
    except InputError as error:
        raise CaseError(path, error.message, error.row) from None


def _check_servo(path, text, servo, prefix=""):
    """The keys ``[servo]`` (``[PREFIX.servo]`` in a machine) needs for its controller, and
    none of another controller's; ``loop_step_s`` defaulted."""
    table = f"{prefix}.servo" if prefix else "servo"
    if "controller" not in servo:
        raise CaseError(path, f"[{table}] controller is required ({', '.join(CONTROLLERS)})",
                        toml_key_line(text, table), f"{table}.controller")
    controller = servo["controller"]
    for key in SERVO_REQUIRED[controller] + ("force_constant_N_per_V",):
        if key not in servo:
            raise CaseError(path, f"[{table}] {key} is required for a {controller} controller",
                            toml_key_line(text, table), f"{table}.{key}")
    foreign = PID_KEYS if controller == "cascade" else CASCADE_KEYS
    for key in foreign:
        if key in servo:
            raise CaseError(path, f"[{table}] {key} does not belong to a {controller} "
                                  f"controller (its keys: {', '.join(SERVO_REQUIRED[controller])}"
                                  + (", tn_s, velocity_feedforward" if controller == "cascade"
                                     else "") + ")",
                            toml_key_line(text, key, table), f"{table}.{key}")
    return {"loop_step_s": DEFAULT_LOOP_STEP_S, **servo}


def _read_text(path):
    """The file's text; a folder, unreadable file or foreign encoding is a :class:`CaseError`."""
    try:
        return read_text(path, "case file")
    except InputError as error:
        raise CaseError(path, error.message, error.row) from None


def _lf_text(path):
    """:func:`_read_text` with LF line ends (CR LF and lone CR turned to LF)."""
    return _read_text(path).replace("\r\n", "\n").replace("\r", "\n")


def check_table(path, text, table, values, prefix=""):
    """``[table]`` (under ``prefix``, ``axes.X`` in a machine) with every key known and
    every value within its rule and range."""
    known = TABLES[table]
    where = f"{prefix}.{table}" if prefix else table
    for key, value in values.items():
        row, column = toml_key_line(text, key, where), f"{where}.{key}"
        if key not in known:
            raise CaseError(path, _unknown_key_message(key, list(known)), row, column)
        problem = _value_problem(known[key], key, value)
        if problem:
            raise CaseError(path, f"{key} {problem}, got {shown_value(value)}", row, column)
    return dict(values)


def _unknown_key_message(key, known):
    hint = "" if "_" in key else " (keys carry their unit as a suffix, e.g. lead_mm)"
    return f"unknown or unit-less key '{key}'{hint}; known: {', '.join(known)}"


def _value_problem(rule, key, value):
    if rule == "support":
        return None if value in SUPPORTS else f"must be one of {', '.join(SUPPORTS)}"
    if rule == "controller":
        return None if value in CONTROLLERS else f"must be one of {', '.join(CONTROLLERS)}"
    try:
        finite_value(value)
    except ValueError as problem:
        return str(problem)
    if rule == "positive" and value <= 0:
        return "must be > 0"
    if rule == "non_negative" and value < 0:
        return "must be >= 0"
    if rule == "positive_integer" and (not isinstance(value, int) or value < 1):
        return "must be a whole number >= 1"
    return range_problem(key, value)


def range_problem(key, value):
    """Why ``value`` lies beyond any physical axis for ``key`` (None when it does not)."""
    low, high = PHYSICAL_RANGE.get(key, (-math.inf, math.inf))
    if low <= value <= high:
        return None
    return f"is beyond any physical axis: expected {low:g} to {high:g}"


def _read_csv(path, spec, bytes_per_row=None):
    """Read a CSV of the format: header row, '#' comment lines, numeric fields only.

    The numbers are parsed by NumPy's C reader; a file it cannot take as one table is read
    again line by line to name the first bad cell; a file whose analysis would not fit at
    ``bytes_per_row`` (the kind's figure, default ``ANALYSIS_BYTES_PER_ROW``) is refused
    before (:func:`check_fits_in_memory`).
    Returns ({column: float array} for the columns present, the data rows'
    :class:`RowLabels`).
    """
    path = Path(path)
    check_fits_in_memory(path, bytes_per_row=bytes_per_row)
    plain = _plain_header(path)
    if plain is None:
        text = _lf_text(path)
        header = _first_record(text)
        if header is None:
            raise CaseError(path, "empty: a header row and at least one data row are needed")
        header_line, header_text, body = header
    else:
        (header_line, header_text), body = plain, None
    names = _check_header(path, [cell.strip() for cell in header_text.split(",")], spec,
                          _row_label(1, header_line))
    table, rows = _table(path, body, header_line, names)
    if table.shape[1] != len(names):
        raise CaseError(path, f"{table.shape[1]} fields where the header has {len(names)}",
                        rows[0], names[min(table.shape[1], len(names) - 1)])
    _check_finite(path, table, rows, names)
    values = {name: table[:, index] for index, name in enumerate(names)}
    for name, column in values.items():
        low, high = PHYSICAL_RANGE.get(name, (-math.inf, math.inf))
        bad = np.flatnonzero((column < low) | (column > high))
        if bad.size:
            value = column[bad[0]]
            raise CaseError(path, f"{value:g} {range_problem(name, value)}", rows[bad[0]], name)
    return values, rows


# Peak memory of the heaviest command per row of a positioning.csv: on 10^7 positioning rows
# (1,000 targets x 5,000 bidirectional runs, benchmarks/bench_positioning_scale.py)
# diagnose peaked at up to 2,555 MB resident and report at up to 2,507 MB, at most 240
# bytes a row above the interpreter's own 150 MB (report on 10^6 rows: 234); since issue
# 35's bounded memory 1,429 and 1,458 MB (about 140 bytes a row), the figure kept for the
# kinds whose analysis was not measured so (a kind measured passes its own to _read_csv:
# feedaxis.measurement.tracking); the text read is held up to three times more (line ends
# normalised) while it is parsed.
ANALYSIS_BYTES_PER_ROW = 250
TEXT_COPIES = 3
SAMPLE_BYTES = 1 << 16  # the file's start, from which its rows are counted
MEMORY_LIMIT_VARIABLE = "FEEDAXIS_MEMORY_LIMIT_MB"  # a lower limit than the machine's
READ_CHUNK_BYTES = 1 << 24  # a large CSV is checked in chunks of this many bytes


def check_fits_in_memory(path, available_bytes=None, bytes_per_row=None):
    """Refuse (:class:`CaseError`) a CSV whose reading and analysis would not fit in the
    memory the machine has available (or the limit ``FEEDAXIS_MEMORY_LIMIT_MB`` sets),
    before reading it: its rows estimated from its size and the lines of its first 64 kB,
    each row costing ``bytes_per_row`` (its kind's analysis at its peak; default
    ``ANALYSIS_BYTES_PER_ROW``), and its text ``TEXT_COPIES`` times where that start shows
    it is read whole (comments, blank lines, CR line ends)."""
    size = path.stat().st_size if path.is_file() else 0
    if size <= SAMPLE_BYTES:
        return
    with open(path, "rb") as stream:
        start = stream.read(SAMPLE_BYTES)
    rows = size * max(start.count(b"\n"), 1) / len(start)
    whole = any(mark in start for mark in (b"#", b"\r", b"\n\n"))
    per_row = ANALYSIS_BYTES_PER_ROW if bytes_per_row is None else bytes_per_row
    needed = (TEXT_COPIES * size if whole else 0) + rows * per_row
    available, where = memory_limit()
    available = available if available_bytes is None else available_bytes
    if available is not None and needed > available:
        raise CaseError(path, f"{size / 1e9:.3g} GB, about {rows:.3g} rows: reading and "
                              f"analysing it needs about {needed / 1e9:.3g} GB of memory "
                              f"and {where.format(f'{available / 1e9:.3g} GB')}; split the "
                              "measurement into several cases or thin it")


def memory_limit():
    """(bytes a case may use, where that figure comes from as a phrase to format with it):
    ``FEEDAXIS_MEMORY_LIMIT_MB`` (megabytes) when set, else
    :func:`available_memory_bytes`."""
    text = os.environ.get(MEMORY_LIMIT_VARIABLE)
    if text is None:
        return available_memory_bytes(), "this machine has {} available"
    try:
        limit_mb = finite_float(text.strip())
    except ValueError:
        limit_mb = None
    if limit_mb is None or limit_mb <= 0:
        raise InputError(f"{MEMORY_LIMIT_VARIABLE}={text!r}: expected a positive number of "
                         "megabytes")
    return limit_mb * 1e6, f"{MEMORY_LIMIT_VARIABLE} allows {{}}"


def available_memory_bytes():
    """Memory the machine can give this process now (bytes): MemAvailable of
    /proc/meminfo, else the physical memory; None when neither is known."""
    try:
        with open("/proc/meminfo", encoding="ascii") as stream:
            for line in stream:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


class RowLabels:
    """The labels of a CSV's data rows (:func:`_row_label`), made when a message needs one.

    ``lines[i]`` is the file line of data row ``i`` (the header is row 1).
    """

    def __init__(self, lines):
        self.lines = lines

    def __len__(self):
        return len(self.lines)

    def __getitem__(self, index):
        return _row_label(int(index) + 2, int(self.lines[index]))


def _plain(body):
    """True when NumPy can read ``body`` (LF line ends) whole: data rows only, no comment
    or blank line."""
    return (bool(body) and not body.isspace() and not body.startswith("\n")
            and "\n\n" not in body and "#" not in body)


def _plain_header(path):
    """(line number, text) of the header of a CSV whose body is :func:`_plain` UTF-8 with
    LF line ends, found by reading the file in chunks of whole lines (never the whole text
    at once: at 10^7 rows the text and its copies were three times the table); None for
    any other file (comments, blank lines, CR line ends, another encoding) or path (a
    folder, an unreadable file), which the whole-text reader reads or refuses."""
    try:
        with open(path, "rb") as stream:
            return _plain_chunks(stream)
    except OSError:
        return None


def _plain_chunks(stream):
    """:func:`_plain_header` of the open binary ``stream``."""
    first = stream.read(READ_CHUNK_BYTES) + stream.readline()
    if first.startswith((b"\xff\xfe", b"\xfe\xff")) or not _plain_bytes(first):
        return None
    try:
        header = _first_record(first.decode("utf-8-sig"))
    except UnicodeDecodeError:
        return None
    if header is None or not _plain(header[2]):
        return None
    while chunk := stream.read(READ_CHUNK_BYTES) + stream.readline():
        # each chunk starts a line: one starting with LF starts with a blank line
        if (b"#" in chunk or b"\n\n" in chunk or chunk.startswith(b"\n")
                or not _plain_bytes(chunk)):
            return None
    return header[:2]


def _plain_bytes(chunk):
    """True when the bytes ``chunk`` (whole lines) are UTF-8 text without CR line ends or
    NUL characters (which the whole-text reader names)."""
    if b"\r" in chunk or b"\x00" in chunk:
        return False
    if chunk.isascii():
        return True
    try:
        chunk.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


def _first_record(text):
    """(line number, text, the text after it) of the first line that is neither blank nor a
    '#' comment; None when there is none. ``text`` has LF line ends."""
    position, number = 0, 1
    while position < len(text):
        end = text.find("\n", position)
        end = len(text) if end < 0 else end
        stripped = text[position:end].strip()
        if stripped and not stripped.startswith("#"):
            return number, text[position:end], text[end + 1:]
        position, number = end + 1, number + 1
    return None


def _table(path, body, header_line, names):
    """The data rows below the header as a float table, and their :class:`RowLabels`.

    A body without comments or blank lines (``body`` None: :func:`_plain_header` found it
    so without holding the text) goes to NumPy whole, read from the file below the header
    (NumPy's reader takes it in chunks: a copy of the text, 4 bytes a character in a
    StringIO, would double the memory of a large case); otherwise its data lines are
    picked out first. Where NumPy refuses, the first bad cell is named.
    """
    if body is None or _plain(body):
        try:
            table = np.loadtxt(path, delimiter=",", comments=None, dtype=float, ndmin=2,
                               encoding="utf-8", skiprows=header_line)
            return table, RowLabels(np.arange(header_line + 1, header_line + 1 + len(table)))
        except ValueError:
            pass  # whitespace-only lines or a bad cell: the line-by-line pass sorts it out
    if body is None:
        body = _first_record(_lf_text(path))[2]
    records = [(number, line) for number, line in enumerate(body.split("\n"), header_line + 1)
               if line.strip() and not line.strip().startswith("#")]
    if not records:
        raise CaseError(path, "no data rows below the header", _row_label(2, header_line + 1))
    rows = RowLabels(np.array([number for number, _ in records]))
    try:
        return _parse([line for _, line in records]), rows
    except ValueError as refused:
        _raise_first_bad_cell(path, records, rows, names)
        raise refused  # NumPy refused a table every cell of which reads: a bug


def _parse(lines):
    """NumPy's C reader over comma-separated lines: a float table, ValueError if it cannot."""
    return np.loadtxt(lines, delimiter=",", comments=None, dtype=float, ndmin=2,
                      encoding=None)


def _raise_first_bad_cell(path, records, rows, names):
    """Raise naming the first row with the wrong number of fields or the first cell that is
    not a finite number, in reading order."""
    for index, (_, line) in enumerate(records):
        cells = line.split(",")
        if len(cells) != len(names):
            raise CaseError(path, f"{len(cells)} fields where the header has {len(names)}",
                            rows[index], names[min(len(cells), len(names) - 1)])
        for name, cell in zip(names, cells):
            _number(path, cell.strip(), rows[index], name)


def _check_finite(path, table, rows, names):
    """Raise naming the first cell (in reading order) that is NaN or infinite (the file's
    text read again only then)."""
    if np.isfinite(table.sum()):  # a NaN or infinity anywhere makes the sum one
        return
    finite = np.isfinite(table)
    if finite.all():  # the sum overflowed
        return
    index = int(np.flatnonzero(~finite.all(axis=1))[0])
    column = int(np.flatnonzero(~finite[index])[0])
    text = _lf_text(path)
    line = text.split("\n")[rows.lines[index] - 1]
    _number(path, line.split(",")[column].strip(), rows[index], names[column])


def _row_label(row, line):
    """Row number counting the header as row 1; the file line too when comments shift it."""
    return f"{row}" if row == line else f"{row} (line {line})"


def _check_header(path, header, spec, row):
    for name in header:
        if name not in spec:
            raise CaseError(path, f"unknown column '{name}'; known: {', '.join(spec)}", row, name)
        if header.count(name) > 1:
            raise CaseError(path, "column appears twice", row, name)
    for name, required in spec.items():
        if required and name not in header:
            raise CaseError(path, "required column is missing", row, name)
    return header


def _number(path, cell, row, column):
    try:
        return finite_float(cell)
    except ValueError as problem:
        accepted = f"; {column} must be {ACCEPTED[column]}" if column in ACCEPTED else ""
        raise CaseError(path, f"{problem}{accepted}", row, column) from None


def checked_run(path, values, rows):
    """The ``run`` column (None when absent), each a whole number >= 1."""
    run = values.get("run")
    if run is not None:
        _first_bad(path, (run < 1) | (run != np.round(run)), rows, "run",
                   "run must be a whole number >= 1")
    return run


def _first_bad(path, mask, rows, column, message):
    """Raise naming the first row where ``mask`` is True."""
    bad = np.flatnonzero(mask)
    if bad.size:
        raise CaseError(path, message, rows[bad[0]], column)


def read_duty(path, length_mm=None):
    """Read duty.csv: contiguous segments from t = 0, durations > 0, feeds >= 0; a segment
    at a feed travels (``from_mm`` != ``to_mm``), one standing still stays put; with
    ``length_mm`` the travel must fit on the screw."""
    path = Path(path)
    values, rows = _read_csv(path, DUTY_COLUMNS)
    start, duration = values["start_s"], values["duration_s"]
    _first_bad(path, duration <= 0, rows, "duration_s", "duration_s must be > 0")
    feed, from_mm, to_mm = values["feed_mm_min"], values["from_mm"], values["to_mm"]
    _first_bad(path, feed < 0, rows, "feed_mm_min",
               "feed_mm_min must be >= 0 (0 means standing still)")
    _first_bad(path, (feed > 0) & (from_mm == to_mm), rows, "to_mm",
               "a segment at a feed > 0 must travel: to_mm equals from_mm (a standstill has "
               "feed_mm_min 0)")
    _first_bad(path, (feed == 0) & (from_mm != to_mm), rows, "to_mm",
               "a standstill (feed_mm_min 0) stays at from_mm: to_mm must equal it")
    _check_travel(path, values, rows, ("from_mm", "to_mm"), length_mm)
    if start[0] != 0.0:
        raise CaseError(path, f"the first segment must start at 0 s, got {start[0]:g}",
                        rows[0], "start_s")
    expected = start[:-1] + duration[:-1]
    tolerance = 1e-9 * np.maximum(1.0, np.abs(expected))
    mismatch = np.flatnonzero(np.abs(start[1:] - expected) > tolerance)
    if mismatch.size:
        i = mismatch[0] + 1
        kind = "overlaps the previous one" if start[i] < expected[i - 1] else "leaves a gap after the previous one"
        raise CaseError(path, f"segment {kind}: starts at {start[i]:g} s, the previous ends at "
                              f"{expected[i - 1]:g} s", rows[i], "start_s")
    return Duty(Segments(start, duration, feed, from_mm, to_mm), values.get("ambient_C"))


def _check_travel(path, values, rows, columns, length_mm):
    """Raise unless the positions in ``columns`` span at most the screw's ``length_mm``."""
    if length_mm is None:
        return
    positions = np.column_stack([values[name] for name in columns])
    span_mm = float(np.ptp(positions))
    if span_mm > length_mm * (1 + 1e-9):
        row, column = np.unravel_index(np.argmax(positions), positions.shape)
        raise CaseError(path, f"the positions span {span_mm:g} mm ({positions.min():g} to "
                              f"{positions.max():g}) on a screw {length_mm:g} mm long "
                              "([screw] length_m of axis.toml)", rows[row], columns[column])


def write_case(folder, axis_values, duty=None, check=None, **samples):
    """Write a case folder atomically: all files appear together or none does.

    Parameters
    ----------
    folder : path
        The case folder to create; it must not exist yet (when another writer creates it
        meanwhile, the first to finish wins and this one is refused).
    axis_values : dict
        The content of axis.toml (``name``, ``screw``, ``motor``, optionally ``servo``).
    duty : dict of {column: array}, optional
        Columns of duty.csv, written in the given order.
    check : callable, optional
        Called with the staged folder before it is published; what it raises leaves
        nothing behind.
    **samples : dict of {column: array}
        Per kind of measurement (``positioning=...``), the columns of its file.
    """
    registered = kinds.kinds()
    unknown = set(samples) - set(registered)
    if unknown:
        raise TypeError(f"no kind of measurement {', '.join(sorted(unknown))}; registered: "
                        f"{', '.join(registered)}")
    files = {registered[kind].file: columns for kind, columns in samples.items()}
    folder = Path(folder)
    if os.path.lexists(folder):
        raise CaseError(folder, "already exists; choose a new case folder")
    with writing(folder):
        folder.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=staging_prefix(folder), dir=folder.parent))
        try:
            (staging / AXIS_FILE).write_text(tomli_w.dumps(axis_values), encoding="utf-8")
            for name, columns in {**files, DUTY_FILE: duty}.items():
                if columns is not None:
                    _write_csv(staging / name, columns)
            if check is not None:
                check(staging)
            os.chmod(staging, umask_mode(0o777))  # mkdtemp's 0700 would hide it from others
            _publish(staging, folder)
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
    return folder


def _publish(staging, folder):
    """Rename the staged folder to ``folder``, refused when another writer got there first
    (a rename never replaces a folder that holds files)."""
    try:
        os.replace(staging, folder)
    except OSError as error:
        if folder.exists() and error.errno in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR):
            raise CaseError(folder, "was created by another run while this one wrote it; "
                                    "that one is kept: choose a new case folder") from None
        raise


def _write_csv(path, columns):
    path.write_text(csv_text(columns), encoding="utf-8")


def csv_text(columns):
    """{column: values} as CSV text in the case format (header row, full float precision:
    each value as Python's shortest repr, which reads back exactly)."""
    cells = [_formatted(name, np.asarray(values, dtype=float)) for name, values in columns.items()]
    return "\n".join([",".join(columns), *map(",".join, zip(*cells))]) + "\n"


def _formatted(name, values):
    """The cells of one column: ``direction`` as +1/-1, ``run`` as a whole number."""
    if name == "direction":
        return [f"{value:+d}" for value in values.astype(int).tolist()]
    if name == "run":
        return list(map(str, values.astype(int).tolist()))
    return list(map(repr, values.tolist()))
