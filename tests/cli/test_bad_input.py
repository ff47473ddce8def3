"""Hard and bad input (issue 15): one test per defect found by probing as a new user would.

Bad input exits 2 with one message naming the file, row and column (or the option or
parameter) and writes nothing; a bug exits 1 with one line pointing at --debug; --json is
strict JSON, errors included.
"""
import json
import os
import signal
import stat

import numpy as np
import pytest

from feedaxis import cli
from feedaxis.case import read_case, write_case
from feedaxis.cli import main
from feedaxis.measurement import Positioning
from feedaxis.stats.spectrum import MAX_FREQUENCIES, amplitude_spectrum
from feedaxis.errors import InputError, json_safe
from feedaxis.fit import NOISE_DOF, FitResult, Statistics, _check_finite
from feedaxis.effects import Model
from feedaxis.effects.catalog import CATALOG

AXIS = {"name": "probe", "screw": {"lead_mm": 5.0}}


def _strict(text):
    """Parse ``text`` as strict JSON: NaN and Infinity are refused."""
    def refuse(constant):
        raise AssertionError(f"non-strict JSON constant {constant}")
    return json.loads(text, parse_constant=refuse)


def small_case(folder, n=40, targets_mm=None, error_um=None):
    targets_mm = np.linspace(0.0, 100.0, n) if targets_mm is None else np.asarray(targets_mm)
    rng = np.random.default_rng(7)
    if error_um is None:
        error_um = 0.02 * targets_mm + rng.normal(0.0, 0.1, targets_mm.size)
    return write_case(folder, AXIS, positioning={"target_mm": targets_mm, "error_um": error_um})


def raw_case(folder, axis_text='[screw]\nlead_mm = 5.0\n', positioning=None):
    folder.mkdir()
    (folder / "axis.toml").write_text(axis_text, encoding="utf-8")
    if positioning is not None:
        data = positioning if isinstance(positioning, bytes) else positioning.encode()
        (folder / "positioning.csv").write_bytes(data)
    return folder


def run(capsys, *argv):
    """Exit code, stdout, stderr of ``feedaxis argv``."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_refused(capsys, argv, *words, code=2):
    exit_code, out, err = run(capsys, *argv)
    assert exit_code == code, err
    assert err.count("\n") == 1 and all(word in err for word in words), err
    return err


# --- tracebacks that should have been messages ------------------------------------------

def test_axis_toml_that_is_a_folder_is_refused_with_its_path(tmp_path, capsys):
    case = raw_case(tmp_path / "c", positioning="target_mm,error_um\n0,1\n")
    (case / "axis.toml").unlink()
    (case / "axis.toml").mkdir()
    assert_refused(capsys, ["compare", case], "axis.toml", "is a folder")


def test_positioning_csv_that_is_a_folder_is_refused_with_its_path(tmp_path, capsys):
    case = raw_case(tmp_path / "c")
    (case / "positioning.csv").mkdir()
    assert_refused(capsys, ["compare", case], "positioning.csv", "is a folder")


def test_unreadable_file_is_refused_with_its_path(tmp_path, capsys):
    if os.geteuid() == 0:
        pytest.skip("root reads every file")
    case = raw_case(tmp_path / "c", positioning="target_mm,error_um\n0,1\n")
    (case / "positioning.csv").chmod(0)
    assert_refused(capsys, ["compare", case], "positioning.csv", "cannot read")


def test_fit_out_an_existing_folder_is_refused_before_fitting(tmp_path, capsys, monkeypatch):
    case = small_case(tmp_path / "c")
    (tmp_path / "out").mkdir()
    monkeypatch.setattr("feedaxis.fit.fit", lambda *a, **k: pytest.fail("fitted anyway"))
    assert_refused(capsys, ["fit", case, "--add", "lead_error", "--out", tmp_path / "out"],
                   str(tmp_path / "out"), "is a folder")


def test_build_fmus_out_an_existing_file_is_refused(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    assert_refused(capsys, ["build-fmus", "--out", tmp_path / "file"], "is a file")
    assert (tmp_path / "file").read_text() == "x"


def test_out_under_a_file_is_refused(tmp_path, capsys):
    case = small_case(tmp_path / "c")
    (tmp_path / "file").write_text("x")
    assert_refused(capsys, ["fit", case, "--out", tmp_path / "file" / "m.toml"], "is a file")


# --- encodings ---------------------------------------------------------------------------

def test_utf8_with_bom_as_spreadsheets_write_it_is_read(tmp_path):
    case = raw_case(tmp_path / "c", positioning="\ufefftarget_mm,error_um\n0,1\n5,2\n")
    (case / "axis.toml").write_text("\ufeff[screw]\nlead_mm = 5.0\n", encoding="utf-8")
    assert read_case(case).positioning.target_mm.tolist() == [0.0, 5.0]


def test_utf16_with_bom_is_read(tmp_path):
    case = raw_case(tmp_path / "c", positioning="target_mm,error_um\n0,1\n5,2\n"
                    .encode("utf-16"))
    assert read_case(case).positioning.error_um.tolist() == [1.0, 2.0]


def test_latin1_is_refused_naming_file_and_line(tmp_path, capsys):
    case = raw_case(tmp_path / "c", positioning="# Messung in \xb5m\ntarget_mm,error_um\n0,1\n"
                    .encode("latin-1"))
    err = assert_refused(capsys, ["compare", case], "positioning.csv", "row 1", "not UTF-8",
                         "0xb5")
    assert "codec" not in err


# --- internal errors that were passed off as bad input ----------------------------------

def test_a_target_beyond_any_axis_is_refused_with_the_limit(tmp_path, capsys):
    case = raw_case(tmp_path / "c", positioning="target_mm,error_um\n0,1\n1e200,2\n")
    assert_refused(capsys, ["diagnose", case], "positioning.csv", "row 3", "'target_mm'",
                   "beyond any physical axis", "100000")


def test_a_youngs_modulus_beyond_any_material_is_refused(tmp_path, capsys):
    case = raw_case(tmp_path / "c", "[screw]\nlead_mm = 5.0\nyoungs_modulus_Pa = 1e-300\n",
                    "target_mm,error_um\n0,1\n5,2\n")
    assert_refused(capsys, ["compare", case], "axis.toml", "row 3", "youngs_modulus_Pa",
                   "beyond any physical axis")


def write_effect(path, body):
    path.write_text("import numpy as np\nfrom feedaxis.effects import Parameter, effect\n\n"
                    "@effect('probe_effect', 'a probe', [Parameter('a_um', 'um', -10, 10)])\n"
                    f"def probe_effect(case, a_um):\n    return {body}\n")
    return path


@pytest.mark.parametrize("body, words", [
    ("np.zeros(3) + a_um", ["shape (3,)", "one error_um per positioning sample"]),
    ("np.full(case.positioning.size, np.nan)", ["not finite"]),
    ("case.positioning.nonexistent", ["raised AttributeError"]),
])
def test_a_user_effect_breaking_the_contract_is_refused_naming_its_file(tmp_path, capsys,
                                                                         body, words):
    case = small_case(tmp_path / "c")
    effects = write_effect(tmp_path / "mine.py", body)
    assert_refused(capsys, ["fit", case, "--effects", effects, "--add", "probe_effect"],
                   "mine.py", "probe_effect", *words)


def test_a_bug_exits_1_with_one_line_and_debug_shows_the_traceback(tmp_path, capsys,
                                                                   monkeypatch):
    case = small_case(tmp_path / "c")

    def broken(*args, **kwargs):
        raise ValueError("a bug, not the user's input")

    monkeypatch.setattr("feedaxis.analysis.compare", broken)
    err = assert_refused(capsys, ["compare", case], "internal error", "bug", "--debug",
                         "ValueError", code=1)
    assert "Traceback" not in err
    with pytest.raises(ValueError, match="a bug"):
        main(["compare", str(case), "--debug"])


def test_a_bug_under_json_is_a_json_error_with_exit_1(tmp_path, capsys, monkeypatch):
    case = small_case(tmp_path / "c")
    monkeypatch.setattr("feedaxis.analysis.compare", lambda *a, **k: 1 / 0)
    code, out, _ = run(capsys, "compare", case, "--json")
    assert code == 1 and "ZeroDivisionError" in _strict(out)["error"]


# --- degenerate data analysed instead of refused ----------------------------------------

@pytest.mark.parametrize("n", [1, 2, NOISE_DOF - 1])
def test_too_few_samples_are_refused_with_what_the_fit_needs(tmp_path, capsys, n):
    case = small_case(tmp_path / "c", n=n)
    assert_refused(capsys, ["fit", case, "--add", "lead_error"], "positioning.csv",
                   f"{n} samples", f"needs at least {NOISE_DOF + 2}", "degrees of freedom")


def test_diagnose_skips_candidates_the_samples_cannot_support(tmp_path):
    from feedaxis.diagnose import diagnose

    case = read_case(small_case(tmp_path / "c", n=NOISE_DOF + 1))
    diagnosis = diagnose(case, Model(), CATALOG)
    wide = [name for name, e in CATALOG.items() if len(e.parameters) >= 2
            and not e.unavailable(case)]
    assert wide and all(name in diagnosis.skipped for name in wide)
    assert "samples" in diagnosis.skipped["lead_error"]  # the others may alias first


def test_deviations_of_1e300_um_are_refused(tmp_path, capsys):
    case = raw_case(tmp_path / "c", positioning="target_mm,error_um\n0,1e300\n5,2\n")
    assert_refused(capsys, ["fit", case, "--out", tmp_path / "m.toml"], "row 2", "error_um",
                   "beyond any physical axis")
    assert not (tmp_path / "m.toml").exists()


def test_a_single_target_is_refused(tmp_path, capsys):
    case = small_case(tmp_path / "c", targets_mm=np.full(30, 12.5))
    assert_refused(capsys, ["fit", case, "--add", "lead_error"], "one target 12.5 mm")


def test_diagnose_of_residuals_equal_to_rounding_is_not_a_crash(tmp_path, capsys):
    """Found by the fuzz test: zero deviations but one denormal (8.6e-283 µm) gave the robust
    drift fit a loss scale whose square underflowed to 0 (NaN inside least_squares)."""
    targets_mm, error_um = np.zeros(26), np.zeros(26)
    targets_mm[24], error_um[25] = 1.0, 8.581239472068811e-283
    case = write_case(tmp_path / "c", AXIS, positioning={
        "target_mm": targets_mm, "error_um": error_um, "direction": -np.ones(26),
        "run": np.r_[np.ones(25), 2.0]})
    assert main(["diagnose", str(case), "--json"]) == 0
    json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("command", [["fit", "{case}", "--add", "lead_error"],
                                     ["diagnose", "{case}"]])
def test_targets_apart_by_less_than_their_resolution_are_one_target(tmp_path, capsys,
                                                                    command):
    """Found by the fuzz test: nine samples at 0 mm and one at 8.6e-283 mm made the
    diagnosis's least squares fail to converge (an internal error, exit 1)."""
    case = small_case(tmp_path / "c", targets_mm=[0.0] * 9 + [8.581239472068811e-283],
                      error_um=np.zeros(10))
    assert_refused(capsys, [part.format(case=case) for part in command],
                   "one target 0 mm (within 0.1 µm)")


@pytest.mark.parametrize("row, message", [
    ("0,60,1000,100,100", "must travel"),
    ("0,60,0,0,100", "stays at from_mm"),
])
def test_duty_segments_that_cannot_be_what_they_say_are_refused(tmp_path, capsys, row,
                                                                message):
    case = raw_case(tmp_path / "c", positioning="target_mm,error_um,time_s\n0,1,0\n5,2,30\n")
    (case / "duty.csv").write_text(f"start_s,duration_s,feed_mm_min,from_mm,to_mm\n{row}\n")
    assert_refused(capsys, ["compare", case], "duty.csv", "row 2", "'to_mm'", message)


def test_travel_longer_than_the_screw_is_refused(tmp_path, capsys):
    case = raw_case(tmp_path / "c", "[screw]\nlead_mm = 5.0\nlength_m = 0.8\n",
                    "target_mm,error_um\n-5000,1\n0,1\n5000,2\n")
    assert_refused(capsys, ["compare", case], "positioning.csv", "row 4", "span 10000 mm",
                   "800 mm long")


def test_a_fit_that_is_not_finite_is_an_error_not_a_result(tmp_path):
    case = read_case(small_case(tmp_path / "c"))
    model = Model([CATALOG["lead_error"]], {"lead_error": {"offset_um": np.nan,
                                                           "slope_um_per_mm": 0.0}})
    residual = np.zeros(3)
    result = FitResult(model, Statistics.of(np.ones(3), residual, 2), np.ones(3), residual)
    with pytest.raises(InputError, match="lead_error.offset_um"):
        _check_finite(result, [Positioning(case)])


# --- memory -----------------------------------------------------------------------------

def test_spectrum_of_nearly_coincident_targets_stays_small():
    position_mm = np.concatenate([np.arange(10) * 1e-9,
                                  [3.0, 7.5, 11.0, 19.0, 23.5, 40.0, 55.0, 61.0, 80.0, 100.0]])
    spectrum = amplitude_spectrum(position_mm, np.sin(position_mm))
    assert 0 < spectrum.wavelength_mm.size <= MAX_FREQUENCIES + 1


# --- JSON --------------------------------------------------------------------------------

def test_json_errors_are_json_on_stdout_with_the_location(tmp_path, capsys):
    case = raw_case(tmp_path / "c", positioning="target_mm,error_um\n0,x\n")
    code, out, _ = run(capsys, "compare", case, "--json")
    error = _strict(out)
    assert code == 2 and error["file"] == str(case / "positioning.csv")
    assert (error["row"], error["column"]) == ("2", "error_um")


def test_json_usage_errors_are_json(capsys):
    code, out, _ = run(capsys, "fit", "--json")
    assert code == 2 and "required" in _strict(out)["error"]


def test_json_of_a_one_row_case_is_a_strict_error(tmp_path, capsys):
    case = small_case(tmp_path / "c", n=1)
    code, out, _ = run(capsys, "diagnose", case, "--json")
    assert code == 2 and "1 samples" in _strict(out)["error"]


def test_json_turns_non_finite_values_into_null(capsys):
    args = cli.build_parser().parse_args(["effects", "--json"])
    cli._emit(args, {"r2": float("nan"), "rms": [np.float64(np.inf), 1.0]}, "")
    assert _strict(capsys.readouterr().out) == {"r2": None, "rms": [None, 1.0]}
    assert json_safe(np.array([1.0, np.nan])) == [1.0, None]


# --- output ------------------------------------------------------------------------------

def test_written_files_follow_the_umask(tmp_path, capsys):
    case = small_case(tmp_path / "c")
    previous = os.umask(0o022)
    try:
        assert run(capsys, "fit", case, "--add", "lead_error", "--out", tmp_path / "m.toml")[0] == 0
        written = write_case(tmp_path / "shared", AXIS, positioning={"target_mm": [0.0, 1.0],
                                                                     "error_um": [0.0, 0.0]})
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / "m.toml").stat().st_mode) == 0o644
    assert stat.S_IMODE(written.stat().st_mode) == 0o755
    assert stat.S_IMODE((written / "positioning.csv").stat().st_mode) == 0o644


def test_ctrl_c_is_reported_once(tmp_path, capsys, monkeypatch):
    from feedaxis.cosim.scenarios import ScenarioInterrupted

    def interrupted(args):
        raise ScenarioInterrupted("interrupted: 12 of 30 samples written to out")

    monkeypatch.setattr(cli, "COMMANDS", [(name, kwargs, options, interrupted if name == "effects"
                                            else handler)
                                           for name, kwargs, options, handler in cli.COMMANDS])
    code, _, err = run(capsys, "effects")
    assert code == 130 and err == "feedaxis: interrupted: 12 of 30 samples written to out\n"


@pytest.mark.parametrize("options, words", [
    (["--amplitude-mm", "1e300"], ["amplitude_mm", "beyond any physical axis"]),
    (["--frequency-hz", "600"], ["frequency_hz", "Nyquist"]),
])
def test_tracking_beyond_the_axis_or_the_step_is_refused(tmp_path, capsys, fmu_paths, options,
                                                          words):
    fmus = next(iter(fmu_paths.values())).parent
    assert_refused(capsys, ["simulate", "tracking", tmp_path / "t", "--fmus", fmus, *options],
                   *words)


def test_tracking_shorter_than_the_settling_time_is_refused_not_nan(tmp_path, capsys):
    err = assert_refused(capsys, ["simulate", "tracking", tmp_path / "t", "--duration-s", 0.5],
                         "duration_s", "must exceed 1 s")
    assert "nan" not in err and not (tmp_path / "t").exists()


@pytest.mark.parametrize("options, words", [
    (["--feed-mm-min", "1e-9"], ["the run would take"]),
    (["--step-ms", "1e-300"], ["the run would take"]),
    (["--spacing-mm", "1e300"], ["the run would take"]),
    (["--targets", "100000000"], ["--targets", "must be 2 to 100000"]),
    (["--targets", "1000", "--runs", "1000"], ["runs", "more than the 100000 samples"]),
])
def test_a_run_that_would_never_end_is_refused(tmp_path, capsys, fmu_paths, options, words):
    fmus = next(iter(fmu_paths.values())).parent
    assert_refused(capsys, ["simulate", "iso230", tmp_path / "c", "--fmus", fmus, *options],
                   *words)
    assert not (tmp_path / "c").exists()


def test_a_thermal_run_with_too_many_passes_is_refused(tmp_path, capsys, fmu_paths):
    fmus = next(iter(fmu_paths.values())).parent
    (tmp_path / "duty.csv").write_text("start_s,duration_s,feed_mm_min,from_mm,to_mm\n"
                                       "0,3600,1000,0,100\n")
    assert_refused(capsys, ["simulate", "thermal", tmp_path / "c", "--duty",
                            tmp_path / "duty.csv", "--targets", "0,50", "--every-s", "1e-9",
                            "--fmus", fmus], "every_s", "more than the 100000 samples")
    assert not (tmp_path / "c").exists()


def test_a_coarse_macro_step_needs_no_thermal_step_option():
    args = cli.build_parser().parse_args(["simulate", "tracking", "out", "--step-ms", "1000"])
    system = cli._axis_system(args)
    assert system.component("ThermalScrew").step_s == pytest.approx(1.0)
    args = cli.build_parser().parse_args(["simulate", "tracking", "out", "--step-ms", "30"])
    assert cli._axis_system(args).component("ThermalScrew").step_s == pytest.approx(0.12)


def test_export_fmu_help_does_not_offer_the_thermal_step(capsys):
    with pytest.raises(SystemExit):
        main(["export-fmu", "--help"])
    assert "--thermal-step-s" not in capsys.readouterr().out


def test_sigint_handler_of_the_cli_is_left_as_found(tmp_path, capsys):
    before = signal.getsignal(signal.SIGINT)
    run(capsys, "effects")
    assert signal.getsignal(signal.SIGINT) is before


# --- --set checked against the FMUs before anything is written -------------------------

@pytest.mark.parametrize("setting, words", [
    ("ThermalScrew.length_m=-1", ["ThermalScrew.length_m", "must be >= 0"]),
    ("ThermalScrew.length_m=0", ["ThermalScrew.length_m", "must be > 0"]),
    ("GeometricError.support=free", ["GeometricError.support", "must be one of"]),
    ("NpidServo.nonlinear=3", ["NpidServo.nonlinear", "Boolean parameter"]),
])
@pytest.mark.parametrize("command, out", [
    (["export-ssp"], "axis.ssp"), (["export-fmu"], "axis.fmu"),
    (["simulate", "iso230"], "case"),
])
def test_set_is_checked_against_the_fmus_before_writing(tmp_path, capsys, fmu_paths, setting,
                                                        words, command, out):
    fmus = next(iter(fmu_paths.values())).parent
    assert_refused(capsys, [*command, tmp_path / out, "--set", setting, "--fmus", fmus],
                   *words)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("argv", [["simulate", "--json", "iso230", "out"],
                                  ["simulate", "iso230", "out", "--json"],
                                  ["fit", "case", "--json"]])
def test_json_is_one_option_wherever_it_stands(argv):
    from feedaxis.cli import _wants_json, build_parser
    assert _wants_json(build_parser().parse_args(argv))
    assert not _wants_json(build_parser().parse_args([a for a in argv if a != "--json"]))
