"""feedaxis import: a generated case written as Renishaw .rtl (and as a wide CSV) and
imported gives back the same samples and ISO 230-2 figures; every structural variation of
the format note reads; every broken file is refused naming file, line and field, exit 2,
nothing written."""
import json
import re

import numpy as np
import pytest

from feedaxis.case import read_case
from feedaxis.cli import main
from feedaxis.importers.rtl import rtl_text
from feedaxis.iso230 import iso230_figures
from feedaxis.physics import geometry

AXIS = 'name = ""\n[screw]\nlead_mm = 10.0\n'
TARGETS_MM = np.array([0.0, 51.23, 99.71, 150.42, 199.05, 250.88, 300.31])
CYCLES = 3


def generated_runs(seed=7):
    """(direction, deviation per target) per rtl run: + and - alternating, lead error,
    backlash and noise from known parameters."""
    rng = np.random.default_rng(seed)
    runs = []
    for _ in range(CYCLES):
        for direction in (1.0, -1.0):
            error_um = (geometry.lead_error_um(TARGETS_MM, 1.5, -0.02)
                        + geometry.backlash_error_um(direction, 3.0)
                        + rng.normal(0.0, 0.4, TARGETS_MM.size))
            runs.append((direction, error_um))
    return runs


def expected_columns(runs, bidirectional=True):
    """The samples the import must give, in the file's order."""
    rows = []
    for number, (direction, error_um) in enumerate(runs, 1):
        order = range(TARGETS_MM.size) if direction > 0 else range(TARGETS_MM.size - 1, -1, -1)
        cycle = (number + 1) // 2 if bidirectional else number
        rows += [(TARGETS_MM[i], error_um[i], direction, cycle) for i in order]
    return [np.array(column) for column in zip(*rows)]


@pytest.fixture
def axis(tmp_path):
    path = tmp_path / "axis.toml"
    path.write_text(AXIS)
    return path


def run_import(tmp_path, axis, name, content, encoding="utf-8"):
    source = tmp_path / name
    source.write_bytes(content.encode(encoding) if isinstance(content, str) else content)
    out = tmp_path / "case"
    return main(["import", str(source), "--axis", str(axis), "--out", str(out)]), out


def assert_same_case(out, runs, bidirectional=True, exact=True):
    positioning = read_case(out).positioning
    target, error, direction, run = expected_columns(runs, bidirectional)
    assert np.array_equal(positioning.target_mm, target)
    assert np.array_equal(positioning.direction, direction)
    assert np.array_equal(positioning.run, run)
    if exact:
        assert np.array_equal(positioning.error_um, error)
    else:
        np.testing.assert_allclose(positioning.error_um, error, rtol=1e-8, atol=1e-12)
    imported = iso230_figures(positioning.target_mm, positioning.error_um, positioning.direction)
    original = iso230_figures(target, error, direction)
    assert imported.keys() == original.keys()
    for key, value in original.items():
        assert imported[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key


def test_rtl_round_trips_a_generated_case_exactly(tmp_path, axis, capsys):
    runs = generated_runs()
    text = rtl_text(TARGETS_MM, runs, {"Machine": "VMC-800", "Axis": "X", "Date": "2026-11-02"},
                    {"Air temp": "20.3", "Mat temp 1": "20.1"})
    code, out = run_import(tmp_path, axis, "x.rtl", text)
    assert code == 0
    assert_same_case(out, runs)
    assert read_case(out).name == "VMC-800 axis X"
    report = capsys.readouterr().out
    assert "USER-TEXT.DATE = 2026-11-02" in report and "Mat temp" not in report
    assert "Air temp" not in report and "air temperature as positioning.csv ambient_C, 20.3" \
        in report and "material temperature as positioning.csv material_C, 20.1" in report
    positioning = read_case(out).positioning
    assert positioning.bidirectional and np.all(positioning.ambient_C == 20.3)
    assert np.all(positioning.material_C == 20.1)


def test_rtl_material_temperatures_and_expansion_make_the_20C_correction(tmp_path, axis,
                                                                         capsys):
    """Mat temp 1..3 (one per run or one for the test) average into material_C, Exp coeff
    (ppm/°C) becomes [screw] expansion_per_K; compare --correct-to-20C then asks for
    nothing the file held, and corrects by α·(T − 20)·X at each sample."""
    runs = generated_runs()
    per_run = " ".join(f"{20.5 + 0.1 * k:g}" for k in range(len(runs)))
    text = rtl_text(TARGETS_MM, runs, {"Axis": "X"},
                    {"Mat temp 1": per_run, "Mat temp 2": "20.7", "Exp coeff": "11.5"})
    code, out = run_import(tmp_path, axis, "x.rtl", text)
    assert code == 0
    case = read_case(out)
    assert case.axis.screw["expansion_per_K"] == 11.5e-6
    expected_C = (np.array([20.5 + 0.1 * k for k in range(len(runs))]) + 20.7) / 2
    rtl_run = 2 * (case.positioning.run - 1) + (case.positioning.direction < 0) + 1
    np.testing.assert_allclose(case.positioning.material_C, expected_C[rtl_run - 1])
    capsys.readouterr()
    assert main(["compare", str(out), "--correct-to-20C", "--json"]) == 0
    corrected = json.loads(capsys.readouterr().out)
    assert main(["compare", str(out), "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)
    assert corrected["figures"] != plain["figures"]


def test_the_bundled_rtl_then_correct_to_20C_runs(tmp_path, capsys):
    from feedaxis.examples import LASER_EXAMPLE

    out = tmp_path / "x-case"
    assert main(["import", str(LASER_EXAMPLE / "X-axis.rtl"), "--axis",
                 str(LASER_EXAMPLE / "axis.toml"), "--out", str(out)]) == 0
    assert "expansion_per_K = 1.17e-05" in capsys.readouterr().out
    assert main(["compare", str(out), "--correct-to-20C"]) == 0
    assert "expansion_per_K" not in capsys.readouterr().err


def test_vendor_csv_headers_with_units_and_a_column_map(tmp_path, axis, capsys):
    vendor = tmp_path / "vendor.csv"
    vendor.write_text("Target (m),Run 1 Fwd (mm),Run 1 Rev (um)\n0,0.0012,3.4\n0.05,0.0008,2.9\n")
    code, out = run_import(tmp_path, axis, "v.csv", vendor.read_text())
    assert code == 0
    samples = read_case(out).positioning
    np.testing.assert_allclose(samples.target_mm, [0, 0, 50, 50])
    np.testing.assert_allclose(samples.error_um, [1.2, 3.4, 0.8, 2.9])
    odd = tmp_path / "odd.csv"
    odd.write_text("Pos,A,B\n0,1.2,3.4\n50,0.8,2.9\n")
    assert main(["import", str(odd), "--axis", str(axis), "--out", str(tmp_path / "o1")]) == 2
    assert "Run <N> Fwd (um)" in capsys.readouterr().err
    assert main(["import", str(odd), "--axis", str(axis), "--out", str(tmp_path / "o2"),
                 "--columns", "Pos=target:mm,A=run1+,B=run1-:um"]) == 0
    np.testing.assert_allclose(read_case(tmp_path / "o2").positioning.error_um,
                               [1.2, 3.4, 0.8, 2.9])


def test_rtl_air_temperature_per_run_becomes_ambient_c(tmp_path, axis, capsys):
    runs = generated_runs()
    per_run = [20.1 + 0.1 * k for k in range(len(runs))]
    text = rtl_text(TARGETS_MM, runs, {}, {"Air temp": " ".join(map(str, per_run))})
    code, out = run_import(tmp_path, axis, "x.rtl", text)
    assert code == 0
    positioning = read_case(out).positioning
    rtl_run = np.repeat(np.arange(len(runs)), TARGETS_MM.size)   # the file's run order
    np.testing.assert_array_equal(positioning.ambient_C, np.array(per_run)[rtl_run])


@pytest.mark.parametrize("value, phrase", [("20.1 20.2", "2 air temperatures: expected one "
                                            "for the test or one per run (Run-count 6)"),
                                           ("250", "air temperature 250 °C is beyond"),
                                           ("warm", "not a number")])
def test_rtl_bad_air_temperature_is_refused(tmp_path, axis, capsys, value, phrase):
    text = rtl_text(TARGETS_MM, generated_runs(), {}, {"Air temp": value})
    code, out = run_import(tmp_path, axis, "x.rtl", text)
    message = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert phrase in message and "field 'Air temp'" in message and "line " in message


def test_axis_toml_name_wins_and_the_files_name_is_reported(tmp_path, capsys):
    axis = tmp_path / "axis.toml"
    axis.write_text('name = "X of mill 4"\n[screw]\nlead_mm = 10.0\n')
    text = rtl_text(TARGETS_MM, generated_runs(), {"Machine": "VMC-800", "Axis": "X"})
    source = tmp_path / "x.rtl"
    source.write_text(text)
    out = tmp_path / "case"
    assert main(["import", str(source), "--axis", str(axis), "--out", str(out), "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["name"] == "X of mill 4" == read_case(out).name
    assert payload["dropped"]["axis name"].startswith("VMC-800 axis X")
    assert payload["samples"] == 42 and payload["targets"] == 7 and payload["runs"] == 3


def _exponents(text):
    return re.sub(r"^(\d+\s+\d+\s+)(\S+)$",
                  lambda m: f"{m.group(1)}{float(m.group(2)):.12E}", text, flags=re.M)


def _spaced_keys(text):
    return (text.replace("Target-count:", "  target-count   :")
            .replace("Run-count:", " RUN-COUNT : ").replace("DEVIATIONS::", "  Deviations  ::")
            .replace("TARGET DATA::", "Target  Data::"))


def _targets_on_the_key_line(text):
    return text.replace("Targets :\r\n", "Targets : ", 1)


VARIATIONS = {
    "CRLF": (lambda runs: rtl_text(TARGETS_MM, runs), True),
    "LF": (lambda runs: rtl_text(TARGETS_MM, runs, newline="\n"), True),
    "targets wrapped by 2": (lambda runs: rtl_text(TARGETS_MM, runs, wrap=2), True),
    "targets on one line": (lambda runs: rtl_text(TARGETS_MM, runs, wrap=100), True),
    "targets start on the key line": (
        lambda runs: _targets_on_the_key_line(rtl_text(TARGETS_MM, runs, wrap=3)), True),
    "exponents": (lambda runs: _exponents(rtl_text(TARGETS_MM, runs, newline="\n")), False),
    "spaces and case in names": (lambda runs: _spaced_keys(rtl_text(TARGETS_MM, runs)), True),
}


@pytest.mark.parametrize("variation", VARIATIONS)
def test_rtl_structural_variations_read(tmp_path, axis, variation):
    make, exact = VARIATIONS[variation]
    runs = generated_runs()
    code, out = run_import(tmp_path, axis, "x.rtl", make(runs))
    assert code == 0
    assert_same_case(out, runs, exact=exact)


def test_rtl_local_code_page_header(tmp_path, axis, capsys):
    runs = generated_runs()
    text = rtl_text(TARGETS_MM, runs, {"By": "Jürgen Groß", "Location": "Halle 3, Süd"})
    code, out = run_import(tmp_path, axis, "x.rtl", text, encoding="cp1252")
    assert code == 0
    assert_same_case(out, runs)
    assert "Jürgen Groß" in capsys.readouterr().out


def test_rtl_unidirectional_runs_are_all_plus(tmp_path, axis):
    runs = [(1.0, error_um) for _, error_um in generated_runs()]
    code, out = run_import(tmp_path, axis, "x.rtl", rtl_text(TARGETS_MM, runs))
    assert code == 0
    assert_same_case(out, runs, bidirectional=False)
    assert not read_case(out).positioning.bidirectional


def _line_of(text, pattern):
    return next(i for i, line in enumerate(text.splitlines(), 1) if re.search(pattern, line))


def _swap_first_backward_rows(text):
    lines = text.split("\n")
    first = next(i for i, line in enumerate(lines) if re.match(r"2\s+7\s", line))
    lines[first], lines[first + 1] = lines[first + 1], lines[first]
    return "\n".join(lines)


def _renumber(text, old, new):
    return re.sub(rf"^{old}(\s+\d+\s+\S+)$", rf"{new}\1", text, flags=re.M)


BROKEN = {
    # name: (mutation of the LF text, field, pattern of the line named, or None)
    "section missing": (lambda t: t.replace("DEVIATIONS::\n", ""), "DEVIATIONS::", None),
    "target count": (lambda t: t.replace("Target-count: 7", "Target-count: 8"), "Target-count",
                     r"Target-count"),
    "target not a number": (lambda t: t.replace("99.7100", "99,71"), "Targets", r"99,71"),
    "targets not increasing": (lambda t: t.replace("150.4200", "10.4200"), "Targets",
                               r"10\.4200"),
    "deviation not a number": (lambda t: re.sub(r"^(1\s+3\s+)\S+$", r"\1abc", t, flags=re.M),
                               "deviation", r"^1\s+3\s+abc"),
    "deviation NaN": (lambda t: re.sub(r"^(1\s+4\s+)\S+$", r"\1nan", t, flags=re.M),
                      "deviation", r"^1\s+4\s+nan"),
    "row missing": (lambda t: re.sub(r"^3\s+5\s+\S+\n", "", t, flags=re.M), "Run-count",
                    r"Run-count"),
    "target number beyond the count": (
        lambda t: re.sub(r"^(4\s+)1(\s+\S+)$", r"\g<1>9\2", t, flags=re.M), "target",
        r"^4\s+9\s"),
    "backward run out of travel order": (_swap_first_backward_rows, "target", r"^2\s+6\s"),
    "even run moving in +": (lambda t: _renumber(_renumber(_renumber(t, 1, "X"), 2, 1), "X", 2),
                             "target", r"^1\s+7\s"),
    "run count zero": (lambda t: t.replace("Run-count:6", "Run-count:0"), "Run-count",
                       r"Run-count"),
    "run count too high": (lambda t: t.replace("Run-count:6", "Run-count:8"), "Run-count",
                           r"Run-count"),
    "row of two fields": (lambda t: re.sub(r"^(5\s+2)\s+\S+$", r"\1", t, flags=re.M), None,
                          r"^5\s+2$"),
}


@pytest.mark.parametrize("name", BROKEN)
def test_rtl_broken_files_are_refused(tmp_path, axis, capsys, name):
    mutate, field, line_pattern = BROKEN[name]
    text = mutate(rtl_text(TARGETS_MM, generated_runs(), newline="\n"))
    code, out = run_import(tmp_path, axis, "broken.rtl", text)
    message = capsys.readouterr().err
    assert code == 2, message
    assert not out.exists() and not list(tmp_path.glob(".case-*"))
    assert "broken.rtl" in message and message.count("\n") == 1
    if field:
        assert f"field '{field}'" in message
    if line_pattern:
        assert f"line {_line_of(text, line_pattern)}" in message


def wide_csv(runs, separator=",", decimal="."):
    names = [f"run{(i // 2) + 1}{'+' if d > 0 else '-'}" for i, (d, _) in enumerate(runs)]
    lines = ["# exported from the laser software", separator.join(["target_mm"] + names)]
    for index, target in enumerate(TARGETS_MM):
        cells = [repr(float(target))] + [repr(float(e[index])) for _, e in runs]
        lines.append(separator.join(cell.replace(".", decimal) for cell in cells))
    return "\n".join(lines) + "\n"


def test_wide_csv_gives_the_same_figures_as_the_rtl(tmp_path, axis):
    runs = generated_runs()
    code, out = run_import(tmp_path, axis, "runs.csv", wide_csv(runs))
    assert code == 0
    positioning = read_case(out).positioning
    target, error, direction, _ = expected_columns(runs)
    imported = iso230_figures(positioning.target_mm, positioning.error_um, positioning.direction)
    for key, value in iso230_figures(target, error, direction).items():
        assert imported[key] == pytest.approx(value, rel=1e-12), key


def test_wide_csv_semicolons_decimal_comma_and_gaps(tmp_path, axis):
    runs = generated_runs()
    text = wide_csv(runs, ";", ",").replace("run1+", "Run 1_up").replace("run1-", "RUN1_down")
    lines = text.splitlines()
    cells = lines[3].split(";")
    cells[2] = ""
    lines[3] = ";".join(cells)
    code, out = run_import(tmp_path, axis, "runs.csv", "\n".join(lines) + "\n")
    assert code == 0
    positioning = read_case(out).positioning
    assert positioning.size == len(runs) * TARGETS_MM.size - 1
    assert set(positioning.run) == {1, 2, 3}
    chosen = (positioning.run == 2) & (positioning.direction == -1)
    np.testing.assert_allclose(positioning.error_um[chosen], runs[3][1])


@pytest.mark.parametrize("mutate, line, field", [
    (lambda t: t.replace("target_mm", "position"), 2, "position"),
    (lambda t: t.replace("run2-", "r2 minus"), 2, "r2 minus"),
    (lambda t: t.replace("run3+", "run1+"), 2, "run1+"),
    (lambda t: t.replace("150.42,", "150.42,x"), 6, "run1+"),
    (lambda t: t.replace("199.05,", "199.05,1,"), 7, None),
])
def test_wide_csv_broken_files_are_refused(tmp_path, axis, capsys, mutate, line, field):
    code, out = run_import(tmp_path, axis, "runs.csv", mutate(wide_csv(generated_runs())))
    message = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert "runs.csv" in message and f"line {line}" in message
    if field:
        assert f"field '{field}'" in message


def test_import_refuses_an_existing_folder_and_unknown_formats(tmp_path, axis, capsys):
    (tmp_path / "case").mkdir()
    code, _ = run_import(tmp_path, axis, "x.rtl", rtl_text(TARGETS_MM, generated_runs()))
    assert code == 2 and "already exists" in capsys.readouterr().err
    (tmp_path / "case").rmdir()
    code, _ = run_import(tmp_path, axis, "x.xls", "nothing")
    assert code == 2 and "unknown format" in capsys.readouterr().err
