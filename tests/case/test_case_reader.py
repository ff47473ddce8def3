"""The vectorised CSV reader of the case format against the per-cell reader it replaced
(issue 25 item 3): the same values and the same first refusal (message, file, row, column)
on the fuzz corpus and on structured near-valid tables.

``reference_read_csv`` is the per-cell reader as it was before NumPy parsed the cells, kept
here only as the reference, with the two rules changed on purpose since: lines end at LF,
CRLF or CR only (a form feed or U+2028 in a comment no longer splits it, issue 26), and a
number is ASCII without Python's ``1_000`` (:func:`feedaxis.errors.finite_float`).
"""
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from feedaxis.case import (PHYSICAL_RANGE, CaseError, _check_header, _read_csv, _read_text,
                           _row_label, range_problem)
from feedaxis.cli import main
from feedaxis.measurement.positioning import POSITIONING_COLUMNS
from feedaxis.measurement.tracking import TRACKING_COLUMNS
from feedaxis.errors import finite_float, text_lines
from test_fuzz import CONTENT, FUZZ

ROOT = Path(__file__).resolve().parents[2]


def reference_read_csv(path, spec):
    """The per-cell reader: every cell through :func:`finite_float` in reading order."""
    records = []
    for line_number, line in enumerate(text_lines(_read_text(path)), 1):
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            records.append((line_number, [cell.strip() for cell in line.split(",")]))
    if not records:
        raise CaseError(path, "empty: a header row and at least one data row are needed")
    header_line, header = records[0]
    names = _check_header(path, header, spec, _row_label(1, header_line))
    if len(records) == 1:
        raise CaseError(path, "no data rows below the header", _row_label(2, header_line + 1))
    row_labels = [_row_label(i + 2, line) for i, (line, _) in enumerate(records[1:])]
    values = {name: np.empty(len(records) - 1) for name in names}
    for index, ((_, cells), row) in enumerate(zip(records[1:], row_labels)):
        if len(cells) != len(names):
            column = names[min(len(cells), len(names) - 1)]
            raise CaseError(path, f"{len(cells)} fields where the header has {len(names)}",
                            row, column)
        for name, cell in zip(names, cells):
            try:
                values[name][index] = finite_float(cell)
            except ValueError as problem:
                raise CaseError(path, str(problem), row, name) from None
    for name, column in values.items():
        low, high = PHYSICAL_RANGE.get(name, (-math.inf, math.inf))
        bad = np.flatnonzero((column < low) | (column > high))
        if bad.size:
            value = column[bad[0]]
            raise CaseError(path, f"{value:g} {range_problem(name, value)}",
                            row_labels[bad[0]], name)
    return values, row_labels


def outcome(reader, path, spec):
    """("values", {column: array}, [row labels]) or ("refused", message)."""
    try:
        values, rows = reader(path, spec)
    except CaseError as error:
        return ("refused", str(error))
    return ("values", values, [rows[i] for i in range(len(rows))])


def assert_same(path, spec):
    new, old = outcome(_read_csv, path, spec), outcome(reference_read_csv, path, spec)
    assert new[0] == old[0], (new, old)
    if new[0] == "refused":
        assert new[1] == old[1]
        return new[0]
    assert list(new[1]) == list(old[1]) and new[2] == old[2]
    for name in old[1]:
        assert np.array_equal(new[1][name], old[1][name])
        assert np.array_equal(np.signbit(new[1][name]), np.signbit(old[1][name]))
    return new[0]


CELLS = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.integers(-10**6, 10**6).map(str),
    st.sampled_from(["", " ", "nan", "-inf", "Infinity", "1e400", "-0", "+1", ".5", "5.",
                     "1_0", "\u0661", "\xa01.5\u3000", "1.5\x0c", "0x1", "1e", "x", " 2 ",
                     "-1e-320", "1e5", "100001", "1,2"]),
)
SEPARATORS = st.sampled_from(["\n", "\r\n", "\r"])
EXTRA_LINES = st.sampled_from(["", "   ", "# comment", "  # indented", "#\u2028x", "#\x0cx",
                               "\x0c", "\u2028", "\t"])


@st.composite
def near_valid_csv(draw):
    """A header of the format's columns, rows of mostly numbers, some odd cells, blank
    lines and comments anywhere, and a few rows with a field too many or too few."""
    names = draw(st.lists(st.sampled_from(list(TRACKING_COLUMNS) + ["target_mm", "error_um"]),
                          min_size=1, max_size=4, unique=True))
    lines = [draw(EXTRA_LINES) for _ in range(draw(st.integers(0, 2)))] + [",".join(names)]
    for _ in range(draw(st.integers(0, 30))):
        if draw(st.integers(0, 9)) == 0:
            lines.append(draw(EXTRA_LINES))
            continue
        width = len(names) + draw(st.sampled_from([0] * 12 + [-1, 1]))
        plain = draw(st.booleans())
        cells = [repr(draw(st.floats(-1e4, 1e4))) if plain else draw(CELLS)
                 for _ in range(max(width, 0))]
        lines.append(",".join(cells))
    separator = draw(SEPARATORS)
    text = separator.join(lines) + draw(st.sampled_from(["", separator, separator * 2]))
    return text.encode(draw(st.sampled_from(["utf-8", "utf-16", "utf-8-sig"])))


@settings(FUZZ, max_examples=600)
@given(data=CONTENT, tracking=st.booleans())
def test_fuzz_corpus_reads_as_the_per_cell_reader_did(tmp_path_factory, data, tracking):
    path = tmp_path_factory.mktemp("csv") / "data.csv"
    path.write_bytes(data)
    assert_same(path, TRACKING_COLUMNS if tracking else POSITIONING_COLUMNS)


@settings(FUZZ, max_examples=300)
@given(data=near_valid_csv())
def test_near_valid_tables_read_as_the_per_cell_reader_did(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("csv") / "data.csv"
    path.write_bytes(data)
    spec = {**TRACKING_COLUMNS, "target_mm": False, "error_um": False}
    assert_same(path, spec)


@settings(FUZZ, max_examples=300)
@given(data=near_valid_csv(), chunk=st.integers(1, 40))
def test_tables_checked_in_small_chunks_read_as_the_per_cell_reader_did(tmp_path_factory,
                                                                        data, chunk):
    """A large file is checked chunk by chunk before NumPy reads it from the file: with
    chunks of a few bytes, every blank line, comment, CR or NUL past the first chunk sends
    the file to the whole-text reader, which refuses or reads it as before."""
    import feedaxis.case as case_module

    path = tmp_path_factory.mktemp("csv") / "data.csv"
    path.write_bytes(data)
    spec = {**TRACKING_COLUMNS, "target_mm": False, "error_um": False}
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(case_module, "READ_CHUNK_BYTES", chunk)
        assert_same(path, spec)


def test_a_plain_file_is_never_held_as_text(tmp_path, monkeypatch):
    """A CSV of data rows only is read by NumPy from the file, its text never held whole;
    a NaN in it is named by its row as before (the text read then)."""
    import feedaxis.case as case_module

    rows = "\n".join(f"{i},{i * 0.5}" for i in range(5000))
    path = tmp_path / "positioning.csv"
    path.write_text(f"target_mm,error_um\n{rows}\n")
    monkeypatch.setattr(case_module, "READ_CHUNK_BYTES", 1000)
    monkeypatch.setattr(case_module, "_read_text", lambda path: pytest.fail("text read"))
    values, _ = _read_csv(path, POSITIONING_COLUMNS)
    assert np.array_equal(values["error_um"], np.arange(5000) * 0.5)
    monkeypatch.undo()
    path.write_text(f"target_mm,error_um\n{rows}\n4,nan\n")
    with pytest.raises(CaseError) as refused:
        _read_csv(path, POSITIONING_COLUMNS)
    assert (refused.value.row, refused.value.column) == ("5002", "error_um")


def test_a_long_file_with_a_bad_cell_at_the_end_is_named_there(tmp_path):
    rows = "\n".join(f"{i},{i * 0.5}" for i in range(5000))
    path = tmp_path / "positioning.csv"
    path.write_text(f"# laser\ntarget_mm,error_um\n{rows}\n4,nan\n")
    assert assert_same(path, POSITIONING_COLUMNS) == "refused"
    try:
        _read_csv(path, POSITIONING_COLUMNS)
    except CaseError as error:
        assert (error.row, error.column) == ("5002 (line 5003)", "error_um")
        assert "must be finite, got 'nan'" in str(error)


def test_the_reader_benchmark_runs_at_a_tiny_size():
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_case_reader.py"),
                             "--smoke"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "reader / np.loadtxt" in result.stdout


def test_a_case_beyond_the_memory_is_refused_before_it_is_read(tmp_path, monkeypatch):
    """A positioning.csv whose analysis would need more memory than the machine has is
    refused with its size and the limit (exit 2), and its text is never read."""
    import feedaxis.case as case_module

    folder = tmp_path / "big"
    folder.mkdir()
    (folder / "axis.toml").write_text('name = "big"\n\n[screw]\nlead_mm = 10.0\n')
    rows = 20_000
    lines = [f"{0.5 * (i % 1000):.4f},{(i % 7) * 0.1:.4f}" for i in range(rows)]
    (folder / "positioning.csv").write_text("target_mm,error_um\n" + "\n".join(lines) + "\n")
    size = (folder / "positioning.csv").stat().st_size
    needed = rows * case_module.ANALYSIS_BYTES_PER_ROW  # a plain file: its text never held

    def never(path):
        raise AssertionError("the file was read")

    monkeypatch.setattr(case_module, "available_memory_bytes", lambda: 0.9 * needed)
    monkeypatch.setattr(case_module, "_read_text", never)
    with pytest.raises(case_module.CaseError) as refused:
        case_module.read_case(folder)
    message = str(refused.value)
    assert "positioning.csv" in message and f"{size / 1e9:.3g} GB" in message
    assert f"{0.9 * needed / 1e9:.3g} GB available" in message
    assert f"about {rows:.3g} rows" in message
    monkeypatch.undo()
    monkeypatch.setattr(case_module, "available_memory_bytes", lambda: 1.1 * needed)
    assert case_module.read_case(folder).positioning.size == rows
    monkeypatch.setattr(case_module, "available_memory_bytes", lambda: 0.9 * needed)
    assert main(["compare", str(folder), "--json"]) == 2


def test_the_memory_limit_variable_refuses_a_case_by_its_size(tmp_path):
    """``FEEDAXIS_MEMORY_LIMIT_MB`` stands for the machine's available memory: a case over
    it is refused before it is read (exit 2, the file, its size and the limit named); a
    value that is not a positive number is refused naming the variable."""
    folder = tmp_path / "big"
    folder.mkdir()
    (folder / "axis.toml").write_text('name = "big"\n\n[screw]\nlead_mm = 10.0\n')
    lines = [f"{0.5 * (i % 1000):.4f},{(i % 7) * 0.1:.4f}" for i in range(20_000)]
    (folder / "positioning.csv").write_text("target_mm,error_um\n" + "\n".join(lines) + "\n")
    size = (folder / "positioning.csv").stat().st_size

    def compare(limit):
        environment = {**os.environ, "FEEDAXIS_MEMORY_LIMIT_MB": limit}
        return subprocess.run([sys.executable, "-m", "feedaxis", "compare", str(folder)],
                              capture_output=True, text=True, env=environment, timeout=120)

    refused = compare("1")
    assert refused.returncode == 2 and refused.stdout == ""
    assert "positioning.csv" in refused.stderr and f"{size / 1e9:.3g} GB" in refused.stderr
    assert "FEEDAXIS_MEMORY_LIMIT_MB allows 0.001 GB" in refused.stderr
    assert compare("1000").returncode == 0
    for bad in ("lots", "-5", "nan"):
        wrong = compare(bad)
        assert wrong.returncode == 2 and "FEEDAXIS_MEMORY_LIMIT_MB" in wrong.stderr


def _tracking_case(folder, rows):
    """A tracking case of ``rows`` samples at 1 ms (a 1 Hz sine followed exactly)."""
    folder.mkdir()
    (folder / "axis.toml").write_text(
        'name = "trace"\n\n[screw]\nlead_mm = 10.0\n\n[servo]\ncontroller = "pid"\n'
        "kp_V_per_mm = 0.9\nki_V_per_mm_s = 0.0006\nkd_V_s_per_mm = 0.005\n"
        "force_constant_N_per_V = 100.0\nloop_step_s = 0.0001\n")
    time_s = np.arange(rows) * 1e-3
    reference_mm = 10.0 * np.sin(2 * np.pi * time_s)
    lines = [f"{t:.3f},{r:.6f},{r:.6f}" for t, r in zip(time_s, reference_mm)]
    (folder / "tracking.csv").write_text("time_s,reference_mm,actual_mm\n" + "\n".join(lines)
                                         + "\n")


def test_a_tracking_case_is_refused_by_its_own_cost_of_a_row(tmp_path, monkeypatch):
    """tracking.csv is estimated at the tracking analysis's own bytes a row, not the
    positioning figure: a limit between the two refuses it (the size, the limit, the
    file named; exit 2, nothing printed on stdout), one above its own accepts it."""
    import feedaxis.case as case_module
    import feedaxis.measurement.tracking as tracking_module

    rows = 5_000
    _tracking_case(tmp_path / "trace", rows)
    per_row = tracking_module.ANALYSIS_BYTES_PER_ROW
    assert per_row > 2 * case_module.ANALYSIS_BYTES_PER_ROW
    between = rows * (per_row + case_module.ANALYSIS_BYTES_PER_ROW) / 2
    monkeypatch.setattr(case_module, "available_memory_bytes", lambda: between)
    with pytest.raises(case_module.CaseError) as refused:
        case_module.read_case(tmp_path / "trace")
    assert "tracking.csv" in str(refused.value) and f"{between / 1e9:.3g} GB available" in \
        str(refused.value)
    monkeypatch.setattr(case_module, "available_memory_bytes", lambda: 1.1 * rows * per_row)
    assert case_module.read_case(tmp_path / "trace").tracking.time_s.size == rows
    monkeypatch.undo()

    def compare(limit_mb):
        environment = {**os.environ, "FEEDAXIS_MEMORY_LIMIT_MB": f"{limit_mb:.6g}"}
        return subprocess.run([sys.executable, "-m", "feedaxis", "compare",
                               str(tmp_path / "trace")], capture_output=True, text=True,
                              env=environment, timeout=300)

    refused = compare(between / 1e6)
    assert refused.returncode == 2 and refused.stdout == ""
    assert "tracking.csv" in refused.stderr and "FEEDAXIS_MEMORY_LIMIT_MB allows" in refused.stderr
    assert compare(1.1 * rows * per_row / 1e6).returncode == 0


def test_the_positioning_columns_are_copies_of_their_own_with_the_values_read(tmp_path):
    """read_positioning keeps each column as an array of its own (the table as read, all
    its columns in one array, is let go), with the values the per-cell reader reads."""
    from feedaxis.measurement.positioning import read_positioning

    path = tmp_path / "positioning.csv"
    path.write_text("target_mm,error_um,direction,run,time_s\n"
                    + "".join(f"{t * 0.5},{0.1 * t - 1},{1 - 2 * (t % 2)},{1 + t // 4},{t}\n"
                              for t in range(12)), encoding="utf-8")
    samples = read_positioning(path)
    expected, _ = reference_read_csv(path, POSITIONING_COLUMNS)
    for name in ("target_mm", "error_um", "direction", "run", "time_s"):
        column = getattr(samples, name)
        assert column.base is None and column.flags.c_contiguous, name
        np.testing.assert_array_equal(column, expected[name], err_msg=name)
