"""Renishaw laser-system linear data file (``.rtl``), as docs/formats/renishaw-rtl.md.

Sections are lines ending in ``::``; keys and section names match without regard to
surrounding spaces or case. Targets (mm) may wrap over several lines; DEVIATIONS lists
``run target deviation_um`` with a backward run's targets in the order they were measured
(last to first). The approach direction follows from that order: a run listing its targets
ascending moved in +, descending in −; in a bidirectional file odd runs must be + and even
runs −. Cycle (ISO run) j is rtl runs 2j − 1 and 2j. CRLF, exponents and a local code page
(cp1252) are read. ENVIRONMENT's air and material temperatures become ``ambient_C`` and
``material_C`` of each sample, its expansion coefficient (ppm/°C) ``[screw] expansion_per_K``.
:func:`rtl_text` writes the same structure, for tests and examples.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..case import PHYSICAL_RANGE
from ..errors import read_text, text_lines
from ..linefile import LineError, number
from . import Measurement

REQUIRED = ("TARGET DATA", "RUNS", "DEVIATIONS")
MAX_COUNT_DIGITS = 9  # a count of targets or runs beyond 10^9 is no laser test
KEPT = {"AXIS", "MACHINE"}
AIR_TEMPERATURE = re.compile(r"air\s*temp\w*\s*:?\s*(.*)", re.I)
MATERIAL_TEMPERATURE = re.compile(r"mat\w*\s*temp\w*\s*(\d)?\s*:?\s*(.*)", re.I)
EXPANSION = re.compile(r"exp\w*\s*coef\w*\s*:?\s*(.*)", re.I)
PPM = 1e-6  # the file's expansion coefficient is in ppm/°C (µm/(m·K))
KEPT_ENVIRONMENT = (AIR_TEMPERATURE, MATERIAL_TEMPERATURE, EXPANSION)


def _key(text):
    return re.sub(r"\s+", " ", text.strip()).upper()


def _sections(path, lines):
    """{SECTION: [(line number, text), ...]} in file order."""
    sections, current = {}, None
    for row, line in enumerate(lines, 1):
        stripped = line.strip()
        if stripped.endswith("::"):
            current = _key(stripped[:-2])
            if current in sections:
                raise LineError(path, "section appears twice", row, current)
            sections[current] = []
        elif stripped and current is not None:
            sections[current].append((row, stripped))
        elif stripped:
            raise LineError(path, "text before the first section", row)
    if not sections:
        raise LineError(path, "no sections: the file is empty or not a .rtl export (one holds "
                              + ", ".join(f"{name}::" for name in REQUIRED) + ")")
    for name in REQUIRED:
        if name not in sections:
            raise LineError(path, "missing section", field=f"{name}::")
    return sections


def _fields(section):
    """{KEY: (value, line)} of the ``key : value`` lines of a section."""
    found = {}
    for row, text in section:
        key, colon, value = text.partition(":")
        if colon:
            found[_key(key)] = (value.strip(), row)
    return found


def _integer(path, fields, key, section_line):
    """The count ``key`` (>= 1) and its line; the field is named as the format writes it."""
    if key not in fields:
        raise LineError(path, "missing", section_line, key.capitalize())
    text, line = fields[key]
    if not re.fullmatch(rf"\+?\d{{1,{MAX_COUNT_DIGITS}}}", text) or int(text) < 1:
        shown = repr(text) if len(text) <= 20 else f"{len(text)} characters"
        raise LineError(path, f"expected a whole number from 1 to 10^{MAX_COUNT_DIGITS}, got "
                              f"{shown}", line, key.capitalize())
    return int(text), line


def _targets(path, section):
    """Target positions (mm): the values after ``Targets :`` up to the next key line."""
    fields = _fields(section)
    count, count_line = _integer(path, fields, "TARGET-COUNT", section[0][0] if section else None)
    if "TARGETS" not in fields:
        raise LineError(path, "missing", count_line, "Targets")
    start = fields["TARGETS"][1]
    values = []
    for row, text in section:
        if row < start:
            continue
        if row > start and ":" in text:
            break
        words = text.partition(":")[2].split() if row == start else text.split()
        values += [(number(w, path, row, "Targets", PHYSICAL_RANGE["target_mm"]), row)
                   for w in words]
    if len(values) != count:
        raise LineError(path, f"{len(values)} targets listed, Target-count says {count}",
                        count_line, "Target-count")
    target_mm = np.array([v for v, _ in values])
    for index in np.flatnonzero(np.diff(target_mm) <= 0):
        raise LineError(path, "targets must increase", values[index + 1][1], "Targets")
    return target_mm


def _deviations(path, section, n_targets, n_runs):
    """{run: [(target number, deviation_um, line), ...]} in listed order."""
    runs = {}
    for row, text in section:
        words = text.split()
        if not runs and _key(text).startswith("RUN TARGET"):
            continue  # the "Run Target Data:" header
        if len(words) != 3:
            raise LineError(path, "expected 'run target deviation'", row)
        run = number(words[0], path, row, "run")
        target = number(words[1], path, row, "target")
        if run != int(run) or not 1 <= run <= n_runs:
            raise LineError(path, f"run must be 1 to Run-count {n_runs}", row, "run")
        if target != int(target) or not 1 <= target <= n_targets:
            raise LineError(path, f"target must be 1 to Target-count {n_targets}",
                            row, "target")
        deviation_um = number(words[2], path, row, "deviation", PHYSICAL_RANGE["error_um"])
        runs.setdefault(int(run), []).append((int(target), deviation_um, row))
    return runs


def _direction(path, run, rows, bidirectional):
    """+1 when the run lists its targets ascending, −1 descending; checked against parity."""
    order = np.diff([target for target, _, _ in rows])
    sign = 1.0 if np.all(order > 0) else -1.0 if np.all(order < 0) else 0.0
    if sign == 0.0:
        raise LineError(path, f"run {run} lists its targets out of travel order",
                        rows[0][2], "target")
    if bidirectional and sign != (1.0 if run % 2 else -1.0):
        raise LineError(path, f"run {run}: in a bidirectional test odd runs move in + "
                              "(targets ascending), even runs in - (descending)",
                        rows[0][2], "target")
    return sign


def read_rtl(path):
    """Read a ``.rtl`` file into a :class:`~feedaxis.importers.Measurement`."""
    path = Path(path)
    sections = _sections(path, text_lines(read_text(path, ".rtl file", "cp1252")))
    target_mm = _targets(path, sections["TARGET DATA"])
    run_fields = _fields(sections["RUNS"])
    n_runs, runs_line = _integer(path, run_fields, "RUN-COUNT",
                                 sections["RUNS"][0][0] if sections["RUNS"] else None)
    runs = _deviations(path, sections["DEVIATIONS"], target_mm.size, n_runs)
    for run in range(1, n_runs + 1):
        listed = sorted(target for target, _, _ in runs.get(run, []))
        if listed != list(range(1, target_mm.size + 1)):
            raise LineError(path, f"run {run} must list every target once "
                                  f"({len(listed)} of {target_mm.size} rows)",
                            runs_line, "Run-count")
    bidirectional = n_runs > 1 and any(
        runs[r][0][0] > runs[r][-1][0] for r in runs) and any(
        runs[r][0][0] < runs[r][-1][0] for r in runs)
    columns = {"target_mm": [], "error_um": [], "direction": [], "run": [], "rtl_run": []}
    for run in range(1, n_runs + 1):
        sign = _direction(path, run, runs[run], bidirectional)
        for target, deviation_um, _ in runs[run]:
            columns["target_mm"].append(target_mm[target - 1])
            columns["error_um"].append(deviation_um)
            columns["direction"].append(sign)
            columns["run"].append((run + 1) // 2 if bidirectional else run)
            columns["rtl_run"].append(run)
    rtl_run = np.array(columns.pop("rtl_run"))
    environment = sections.get("ENVIRONMENT", [])
    air_C = _temperatures(path, environment, n_runs, AIR_TEMPERATURE, "Air temp", "air")
    material_C = _temperatures(path, environment, n_runs, MATERIAL_TEMPERATURE, "Mat temp",
                               "material")
    return Measurement(*(np.array(columns[k], dtype=float) for k in columns),
                       name=_name(sections), dropped=_dropped(sections),
                       ambient_C=None if air_C is None else air_C[rtl_run - 1],
                       material_C=None if material_C is None else material_C[rtl_run - 1],
                       expansion_per_K=_expansion_per_K(path, environment))


def _name(sections):
    fields = _fields(sections.get("USER-TEXT", []))
    parts = [fields[k][0] for k in ("MACHINE", "AXIS") if fields.get(k, ("",))[0]]
    return " axis ".join(parts)


def _temperatures(path, section, n_runs, pattern, field, what):
    """The temperature (°C) of each rtl run from the ENVIRONMENT lines ``pattern`` matches
    (``Air temp``; ``Mat temp 1`` to ``3``, averaged over the sensors given): each one value
    for the whole test or one per run; None when the file gives none."""
    sensors = []
    for row, text in section:
        match = pattern.fullmatch(text)
        if match:
            values = np.array([number(word, path, row, field)
                               for word in match.groups()[-1].replace(",", " ").split()])
            if values.size not in (1, n_runs):
                raise LineError(path, f"{values.size} {what} temperatures: expected one for "
                                      f"the test or one per run (Run-count {n_runs})", row,
                                field)
            low, high = PHYSICAL_RANGE["ambient_C"]
            for value in values[(values < low) | (values > high)]:
                raise LineError(path, f"{what} temperature {value:g} °C is beyond {low:g} to "
                                      f"{high:g} °C", row, field)
            sensors.append(np.broadcast_to(values, (n_runs,)).astype(float))
    return np.mean(sensors, axis=0) if sensors else None


def _expansion_per_K(path, section):
    """The expansion coefficient (1/K) of the ENVIRONMENT line ``Exp coeff`` (ppm/°C);
    None when the file gives none."""
    for row, text in section:
        match = EXPANSION.fullmatch(text)
        if match:
            low, high = PHYSICAL_RANGE["expansion_per_K"]
            ppm = number(match.group(1).strip(), path, row, "Exp coeff", (low / PPM, high / PPM))
            return float(f"{ppm!r}e-6")  # exactly the decimal the file wrote, times 10^-6
    return None


def _dropped(sections):
    """{section.key: value} of the metadata the case format cannot hold (the air and
    material temperatures and the expansion coefficient it holds)."""
    dropped = {}
    for section in ("HEADER", "USER-TEXT", "ENVIRONMENT"):
        lines = [(row, text) for row, text in sections.get(section, [])
                 if not (section == "ENVIRONMENT"
                         and any(p.fullmatch(text) for p in KEPT_ENVIRONMENT))]
        for key, (value, _) in _fields(lines).items():
            if not (section == "USER-TEXT" and key in KEPT) and value:
                dropped[f"{section}.{key}"] = value
        for row, text in lines:
            if ":" not in text:
                dropped[f"{section}.line {row}"] = text
    return dropped


def rtl_text(target_mm, runs, user_text=None, environment=None, wrap=5, newline="\r\n"):
    """An ``.rtl`` file's text: ``runs`` is a list of (direction, deviations_um in target
    order); a − run is listed from the last target to the first, as measured."""
    lines = ["HEADER::", "File type  : rtl", "Owner      : feedaxis", "Version no : 1",
             "TARGET DATA::", "Filetype  : ISO", f"Target-count: {len(target_mm)}", "Targets :"]
    lines += [" ".join(f"{t:.4f}" for t in target_mm[i:i + wrap])
              for i in range(0, len(target_mm), wrap)]
    lines += ["Flags: 0 0 2 0", "USER-TEXT::"]
    lines += [f"{key}: {value}" for key, value in (user_text or {}).items()]
    lines += ["RUNS::", f"Run-count:{len(runs)}", "DEVIATIONS::", "Run Target Data:"]
    for run, (direction, deviation_um) in enumerate(runs, 1):
        order = range(len(target_mm)) if direction > 0 else range(len(target_mm) - 1, -1, -1)
        lines += [f"{run}   {i + 1}   {float(deviation_um[i])!r}" for i in order]
    lines += ["ENVIRONMENT::"] + [f"{key} {value}" for key, value in (environment or {}).items()]
    lines.append("EOF::")
    return newline.join(lines) + newline
