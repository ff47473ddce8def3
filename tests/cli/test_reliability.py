"""Issue 26: bad input never reaches the bug path, nothing is left half-written, every input
finishes in bounded time. One test per failure the issue lists, in its order.

Bad input exits 2 with one line naming the file (row, column) or the parameter; a full or
read-only disk exits 2 naming the file; Ctrl-C exits 130 with one line; what is refused
leaves nothing behind.
"""
import errno
import json
import os
import signal
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from feedaxis.case import read_case, write_case
from feedaxis.cli import main
from feedaxis.comptable import fanuc, siemens
from feedaxis.errors import InputError
from feedaxis.fmu_build import FMU_NAMES
from feedaxis.importers.rtl import rtl_text
from feedaxis.linefile import LineError
from feedaxis.output import built_once, write_atomically
from feedaxis.physics.servo import MAX_INTERVAL_STEPS
from test_bad_input import AXIS, assert_refused, raw_case, run, small_case, write_effect

ROOT = Path(__file__).resolve().parents[2]
FEEDAXIS = [sys.executable, "-m", "feedaxis"]
TRACKING_AXIS = ('[screw]\nlead_mm = 1.0\n[servo]\ncontroller = "pid"\nkp_V_per_mm = 0.8998\n'
                 "ki_V_per_mm_s = 0.0006077\nkd_V_s_per_mm = 0.005155\n"
                 "force_constant_N_per_V = 100.0\n")
WIDE_CSV = "target_mm,run1+,run1-\n0,1.0,2.0\n50,1.5,2.5\n100,1.2,2.2\n"


def feedaxis(*argv, **kwargs):
    """The console script in a fresh process: (exit code, stdout, stderr)."""
    result = subprocess.run([*FEEDAXIS, *map(str, argv)], capture_output=True, text=True,
                            timeout=600, **kwargs)
    return result.returncode, result.stdout, result.stderr


def tracking_case(folder, time_s=None):
    """A tracking case of a damped sine, 3 s at 1 ms unless ``time_s`` is given."""
    time_s = np.arange(0.0, 3.0, 1e-3) if time_s is None else np.asarray(time_s, dtype=float)
    reference_mm = 10.0 * np.sin(2 * np.pi * 0.4 * time_s)
    folder.mkdir()
    (folder / "axis.toml").write_text(TRACKING_AXIS)
    lines = ["time_s,reference_mm,actual_mm"] + [
        f"{t!r},{r!r},{r - 0.01!r}" for t, r in zip(time_s.tolist(), reference_mm.tolist())]
    (folder / "tracking.csv").write_text("\n".join(lines) + "\n")
    return folder


def default_sigint():
    """In a child: Ctrl-C as a terminal delivers it (a shell's background job, which this
    test may run in, starts its children with SIGINT ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def fmu_folder(fmu_paths):
    return next(iter(fmu_paths.values())).parent


# --- numbers beyond a float, over-long integers, deep nesting ---------------------------

def test_an_integer_beyond_a_float_in_axis_toml_is_refused_at_its_key(tmp_path, capsys):
    case = raw_case(tmp_path / "c", "[screw]\nlead_mm = 1" + "0" * 400 + "\n",
                    "target_mm,error_um\n0,1\n5,2\n")
    err = assert_refused(capsys, ["compare", case], "axis.toml", "row 2", "screw.lead_mm",
                         "beyond the range of a number", "an integer of 401 digits")
    assert "0" * 100 not in err


@pytest.mark.parametrize("where", ["axis.toml", "model", ".rtl Target-count"])
def test_an_integer_of_more_than_4300_digits_is_refused_at_its_line(tmp_path, capsys, where):
    digits = "1" + "0" * 5000
    case = small_case(tmp_path / "c")
    if where == "axis.toml":
        (case / "axis.toml").write_text(f"[screw]\nlead_mm = {digits}\n")
        argv, words = ["compare", case], ["axis.toml", "row 2", "4300 digits"]
    elif where == "model":
        (tmp_path / "m.toml").write_text(f"[lead_error]\noffset_um = {digits}\n"
                                         "slope_um_per_mm = 0\n")
        argv, words = ["compare", case, "--model", tmp_path / "m.toml"], ["m.toml", "row 2",
                                                                          "4300 digits"]
    else:
        text = rtl_text([0.0, 5.0], [(1.0, [0.1, 0.2])]).replace("Target-count: 2",
                                                                  f"Target-count: {digits}")
        (tmp_path / "x.rtl").write_text(text)
        argv = ["import", tmp_path / "x.rtl", "--axis", case, "--out", tmp_path / "new"]
        words = ["x.rtl", "line 7", "Target-count", "5001 characters"]
    assert_refused(capsys, argv, *words)


@pytest.mark.parametrize("file", ["axis.toml", "model"])
def test_toml_nested_500_deep_is_refused_at_its_line(tmp_path, capsys, file):
    case = small_case(tmp_path / "c")
    nested = "x = " + "[" * 500 + "]" * 500 + "\n"
    if file == "axis.toml":
        (case / "axis.toml").write_text("[screw]\nlead_mm = 5.0\n" + nested)
        argv, words = ["compare", case], ["axis.toml", "row 3"]
    else:
        (tmp_path / "m.toml").write_text(nested)
        argv, words = ["compare", case, "--model", tmp_path / "m.toml"], ["m.toml", "row 1"]
    assert_refused(capsys, argv, *words, "nested more than 64 deep")


# --- import reads as the case files do -------------------------------------------------

@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16"])
def test_import_reads_an_axis_toml_with_a_bom_or_in_utf16(tmp_path, capsys, encoding):
    (tmp_path / "axis.toml").write_bytes(AXIS_TEXT.encode(encoding))
    (tmp_path / "w.csv").write_bytes(WIDE_CSV.encode(encoding))
    code, _, err = run(capsys, "import", tmp_path / "w.csv", "--axis", tmp_path / "axis.toml",
                       "--out", tmp_path / "case")
    assert code == 0, err
    assert read_case(tmp_path / "case").positioning.size == 6


AXIS_TEXT = "[screw]\nlead_mm = 5.0\nlength_m = 0.5\n"


def test_import_of_a_latin1_csv_is_refused_naming_the_line(tmp_path, capsys):
    (tmp_path / "axis.toml").write_text(AXIS_TEXT)
    (tmp_path / "w.csv").write_bytes(("# Abweichung in \xb5m\n" + WIDE_CSV).encode("latin-1"))
    assert_refused(capsys, ["import", tmp_path / "w.csv", "--axis", tmp_path / "axis.toml",
                            "--out", tmp_path / "case"], "w.csv", "row 1", "not UTF-8", "0xb5")
    assert not (tmp_path / "case").exists()


@pytest.mark.parametrize("command", ["simulate", "import", "build-fmus"])
def test_out_a_dangling_symbolic_link_is_refused(tmp_path, capsys, fmu_paths, command):
    (tmp_path / "axis.toml").write_text(AXIS_TEXT)
    (tmp_path / "w.csv").write_text(WIDE_CSV)
    out = tmp_path / "out"
    out.symlink_to(tmp_path / "nowhere")
    argv = {"simulate": ["simulate", "tracking", out, "--fmus", fmu_folder(fmu_paths)],
            "import": ["import", tmp_path / "w.csv", "--axis", tmp_path / "axis.toml",
                       "--out", out],
            "build-fmus": ["build-fmus", "--out", out]}[command]
    assert_refused(capsys, argv, str(out), "symbolic link", "does not exist")
    assert out.is_symlink() and not (tmp_path / "nowhere").exists()


def test_import_into_a_read_only_folder_is_refused_naming_it(tmp_path):
    (tmp_path / "axis.toml").write_text(AXIS_TEXT)
    (tmp_path / "w.csv").write_text(WIDE_CSV)
    code, err, left = on_small_disk(tmp_path, ["import", tmp_path / "w.csv", "--axis",
                                               tmp_path / "axis.toml", "--out", "DISK/case"],
                                    read_only=True)
    assert code == 2 and err.count("\n") == 1, err
    assert "DISK/case" in err and "read-only file system" in err and left == []


# --- user effects held to their contract ------------------------------------------------

EFFECT_HEADER = "import numpy as np\nfrom feedaxis.effects import Parameter, effect\n\n"


def write_effect_file(path, parameters="[Parameter('a_um', 'um', -10, 10)]",
                      body="a_um + 0 * case.positioning.target_mm", guess=None, extra=""):
    guess_code = f", guess=lambda case, residual: {guess}" if guess else ""
    path.write_text(EFFECT_HEADER + extra +
                    f"@effect('probe_effect', 'a probe', {parameters}{guess_code})\n"
                    f"def probe_effect(case, **values):\n    a_um = next(iter(values.values()))\n"
                    f"    return {body}\n")
    return path


@pytest.mark.parametrize("options, words", [
    ({"body": "1e300 + 0 * case.positioning.target_mm"}, ["returned 1e+300 um",
                                                          "beyond any physical axis"]),
    ({"body": "(1 + 1j) * np.ones(case.positioning.size)"}, ["not finite real numbers"]),
    ({"parameters": "[Parameter('a_um', 'um', 5, 5)]"}, ["lower bound 5 must be below"]),
    ({"parameters": "[Parameter('a_um', 'um', 5, -5)]"}, ["lower bound 5 must be below"]),
    ({"parameters": "[Parameter('a_um', 'um', -np.inf, 5)]"}, ["must be finite"]),
    ({"guess": "{'b_um': 1.0}"}, ["guess() must return", "a_um", "['b_um']"]),
    ({"extra": "import sys\nsys.exit(3)\n"}, ["called sys.exit(3)"]),
])
def test_a_user_effect_breaking_its_contract_exits_2_naming_its_file(tmp_path, capsys,
                                                                    options, words):
    case = small_case(tmp_path / "c")
    effects = write_effect_file(tmp_path / "mine.py", **options)
    assert_refused(capsys, ["fit", case, "--effects", effects, "--add", "probe_effect"],
                   "mine.py", *words)


def test_sys_exit_inside_an_effect_call_is_refused_not_obeyed(tmp_path, capsys):
    case = small_case(tmp_path / "c")
    effects = write_effect(tmp_path / "mine.py", "__import__('sys').exit(4)")
    assert_refused(capsys, ["fit", case, "--effects", effects, "--add", "probe_effect"],
                   "mine.py", "called sys.exit(4)")


def test_print_in_a_user_effect_leaves_json_strict(tmp_path, capsys):
    case = small_case(tmp_path / "c")
    effects = write_effect_file(tmp_path / "mine.py", extra="print('loading my effect')\n",
                                body="print('evaluating') or a_um + 0 * case.positioning.target_mm")
    code, out, err = run(capsys, "fit", case, "--effects", effects, "--add", "probe_effect",
                         "--json")
    assert code == 0 and json.loads(out)["effects"] == ["probe_effect"]
    assert "loading my effect" in err and "evaluating" in err


def test_an_effects_file_that_is_not_python_is_refused(tmp_path, capsys):
    (tmp_path / "x.toml").write_text("a = 1\n")
    assert_refused(capsys, ["effects", "--effects", tmp_path / "x.toml"], "x.toml",
                   "Python source ending in .py")


# --- tracking model values --------------------------------------------------------------

PLANT = ("[servo_plant]\nplant_gain_mm_per_Vs2 = {gain}\nplant_damping_per_s = {damping}\n"
         "plant_stiffness_per_s2 = {stiffness}\ndelay_s = 0.0012\n")


@pytest.mark.parametrize("command", ["compare", "fit", "diagnose"])
@pytest.mark.parametrize("values, words", [
    ({"gain": 2.55e16, "damping": 163.0, "stiffness": 1.7e-159},
     ["servo_plant.plant_gain_mm_per_Vs2", "beyond what the effect allows"]),
    ({"gain": 1e7, "damping": 0.0, "stiffness": 0.0},
     ["the closed position loop runs away", "plant gain 1e+07"]),
])
def test_a_tracking_model_beyond_any_plant_is_refused(tmp_path, capsys, command, values,
                                                      words):
    case = tracking_case(tmp_path / "t")
    (tmp_path / "m.toml").write_text(PLANT.format(**values))
    assert_refused(capsys, [command, case, "--model", tmp_path / "m.toml"], *words)


# --- a full disk -------------------------------------------------------------------------

def on_small_disk(tmp_path, argv, read_only=False):
    """Run ``feedaxis argv`` with ``DISK`` in it a 64 kB tmpfs (read-only if asked) mounted
    in a private mount namespace; (exit code, stderr, entries left on the disk as
    "f path" for a file, "d path" for a folder)."""
    disk, listing = tmp_path / "disk", tmp_path / "listing.txt"
    disk.mkdir()
    options = "ro,size=64k" if read_only else "size=64k"
    script = (f'mount -t tmpfs -o {options} tmpfs "$DISK" || exit 99\n"$@"\ncode=$?\n'
              f'find "$DISK" -mindepth 1 -printf "%y %P\\n" > "{listing}"\nexit $code\n')
    user = [] if os.geteuid() == 0 else ["--map-root-user"]
    argv = [str(a).replace("DISK", str(disk)) for a in argv]
    try:
        result = subprocess.run(["unshare", "--mount", *user, "sh", "-c", script, "sh",
                                 *FEEDAXIS, *argv], capture_output=True, text=True,
                                timeout=600, env={**os.environ, "DISK": str(disk)})
    except FileNotFoundError:
        pytest.skip("needs unshare (util-linux) to mount a small disk")
    if result.returncode == 99 or not listing.exists():
        pytest.skip(f"cannot mount a small tmpfs here: {result.stderr.strip()[-200:]}")
    left = [line for line in listing.read_text().splitlines() if line]
    return result.returncode, result.stderr.replace(str(disk), "DISK"), left


@pytest.mark.parametrize("argv, named", [
    (["report", "{case}", "--model", "{model}", "--out", "DISK/r.html"], "DISK/r.html"),
    (["simulate", "tracking", "DISK/t", "--fmus", "{fmus}", "--duration-s", "3"], "DISK/t"),
    (["build-fmus", "--out", "DISK/fmus"], "DISK/fmus/NpidServo.fmu"),
    (["export-ssp", "DISK/a.ssp", "--fmus", "{fmus}"], "DISK/a.ssp"),
    (["export-fmu", "DISK/a.fmu", "--fmus", "{fmus}"], "DISK/a.fmu"),
    (["demo", "--out", "DISK/demo"], "DISK/demo"),
])
def test_a_full_disk_exits_2_naming_the_file_and_leaves_nothing(tmp_path, fmu_paths, argv,
                                                                named):
    case = small_case(tmp_path / "c")
    (tmp_path / "m.toml").write_text("[lead_error]\noffset_um = 0.1\nslope_um_per_mm = 0.01\n")
    argv = [a.format(case=case, model=tmp_path / "m.toml", fmus=fmu_folder(fmu_paths))
            for a in argv]
    code, err, left = on_small_disk(tmp_path, argv)
    assert code == 2 and err.endswith(": cannot write: no space left on the device\n"), err
    assert err.splitlines()[-1].startswith(f"feedaxis: {named}"), err
    assert [entry for entry in left if not entry.startswith("d ")] == []
    assert not [entry for entry in left if "/." in f"/{entry[2:]}"]  # no staging left


# --- FMUs of --fmus ---------------------------------------------------------------------

@pytest.mark.parametrize("member", ["../evil.txt", "/etc/evil", "a\\..\\evil"])
def test_fmus_holding_paths_outside_their_folder_are_refused(tmp_path, capsys, fmu_paths,
                                                             member):
    folder = tmp_path / "fmus"
    folder.mkdir()
    for path in fmu_paths.values():
        (folder / path.name).write_bytes(path.read_bytes())
    with zipfile.ZipFile(folder / "NpidServo.fmu", "a") as archive:
        archive.writestr(member, "x")
    assert_refused(capsys, ["simulate", "tracking", tmp_path / "t", "--fmus", folder],
                   "NpidServo.fmu", "unpack outside", "unsafe")
    assert not (tmp_path / "t").exists() and not (tmp_path / "evil.txt").exists()


# --- nothing written that is then refused, nothing half-written -------------------------

@pytest.mark.parametrize("cell, axis_text, words", [
    ("1e300", AXIS_TEXT, ["w.csv", "line 2", "run1+", "beyond any physical axis"]),
    ("1.0", "[screw]\nlead_mm = 5.0\nlength_m = 0.01\n", ["w.csv", "target_mm",
                                                         "span 100 mm", "10 mm long"]),
])
def test_import_refuses_before_it_writes(tmp_path, capsys, cell, axis_text, words):
    (tmp_path / "axis.toml").write_text(axis_text)
    (tmp_path / "w.csv").write_text(WIDE_CSV.replace("0,1.0,", f"0,{cell},"))
    assert_refused(capsys, ["import", tmp_path / "w.csv", "--axis", tmp_path / "axis.toml",
                            "--out", tmp_path / "case"], *words)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["axis.toml", "w.csv"]


def test_import_reads_the_staged_case_back_before_publishing(tmp_path, monkeypatch, capsys):
    """Whatever the case reader would refuse is refused before the folder appears."""
    from feedaxis import importers

    def refuse(staged):
        read_case(staged)
        raise InputError("refused after staging", path=tmp_path / "w.csv")

    monkeypatch.setattr(importers, "_check_case", lambda path, staged: refuse(staged))
    (tmp_path / "axis.toml").write_text(AXIS_TEXT)
    (tmp_path / "w.csv").write_text(WIDE_CSV)
    assert_refused(capsys, ["import", tmp_path / "w.csv", "--axis", tmp_path / "axis.toml",
                            "--out", tmp_path / "case"], "refused after staging")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["axis.toml", "w.csv"]


def test_of_two_writers_of_one_case_folder_the_first_wins_the_other_says_so(tmp_path):
    folder = tmp_path / "case"
    first = {"target_mm": [0.0, 1.0], "error_um": [1.0, 1.0]}

    def other_writer_finishes_first(staged):
        write_case(folder, AXIS, positioning=first)

    with pytest.raises(InputError, match="created by another run"):
        write_case(folder, AXIS, positioning={"target_mm": [0.0, 2.0], "error_um": [0.0, 0.0]},
                   check=other_writer_finishes_first)
    assert read_case(folder).positioning.target_mm.tolist() == [0.0, 1.0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["case"]


def test_concurrent_writers_of_one_file_each_publish_it_whole(tmp_path):
    path = tmp_path / "m.toml"
    contents = [(str(i) * 200_000).encode() for i in range(6)]
    threads = [threading.Thread(target=write_atomically, args=(path, c)) for c in contents]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert path.read_bytes() in contents and [p.name for p in tmp_path.iterdir()] == ["m.toml"]


def test_a_cached_folder_is_built_once_and_never_left_half_built(tmp_path):
    """``built_once`` (the FMU cache, the servo kernel): built once, an incomplete folder
    replaced, a failed build leaves nothing, a builder that lost the race uses the winner's."""
    def complete(folder):
        return (folder / "done").is_file()

    def build(staging):
        builds.append(staging.name)
        (staging / "done").write_text("mine")

    builds, folder = [], tmp_path / "cache" / "kernel"
    assert built_once(folder, build, complete) == folder
    assert built_once(folder, build, complete) == folder and len(builds) == 1
    (folder / "done").unlink()
    built_once(folder, build, complete)
    assert len(builds) == 2 and complete(folder)

    def failing(staging):
        (staging / "half").write_text("")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        built_once(tmp_path / "cache" / "other", failing, complete)

    def racing(staging):
        winner = tmp_path / "cache" / "raced"
        winner.mkdir()
        (winner / "done").write_text("winner")
        (staging / "done").write_text("loser")

    assert (built_once(tmp_path / "cache" / "raced", racing, complete) / "done").read_text() \
        == "winner"
    assert sorted(p.name for p in (tmp_path / "cache").iterdir()) == ["kernel", "raced"]


def assert_complete_fmus(folder, reference_paths):
    """Every FMU in ``folder`` is whole: its zip reads, it holds the members of a complete
    build (the host layer included) and fmpy's validation finds nothing."""
    from fmpy.validation import validate_fmu

    for path in folder.glob("*.fmu"):
        with zipfile.ZipFile(path) as archive:
            assert archive.testzip() is None, path
            members = sorted(archive.namelist())
        with zipfile.ZipFile(reference_paths[path.stem]) as archive:
            assert members == sorted(archive.namelist()), path
        assert validate_fmu(str(path)) == [], path
    assert {p.name for p in folder.iterdir()} <= {f"{name}.fmu" for name in FMU_NAMES}


def test_two_builds_into_one_folder_each_finish_and_leave_whole_fmus(tmp_path, fmu_paths):
    out = tmp_path / "fmus"
    builds = [subprocess.Popen([*FEEDAXIS, "build-fmus", "--out", str(out)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
              for _ in range(2)]
    results = [(b.wait(timeout=600), b.stderr.read()) for b in builds]
    assert all(code == 0 for code, _ in results), results
    assert sorted(p.stem for p in out.iterdir()) == sorted(FMU_NAMES)
    assert_complete_fmus(out, fmu_paths)


@pytest.mark.parametrize("delay_s", [0.0, 1.0, 3.0])
def test_ctrl_c_during_build_fmus_exits_130_and_leaves_only_whole_fmus(tmp_path, fmu_paths,
                                                                      delay_s):
    """Ctrl-C ``delay_s`` after the build began (its folder appeared: Python's own start-up,
    before any feedaxis code runs, is not what is tested here)."""
    out = tmp_path / "fmus"
    build = subprocess.Popen([*FEEDAXIS, "build-fmus", "--out", str(out)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             preexec_fn=default_sigint)
    while not out.exists() and build.poll() is None:
        time.sleep(0.01)
    try:
        build.wait(timeout=delay_s)
    except subprocess.TimeoutExpired:
        build.send_signal(signal.SIGINT)
    code, err = build.wait(timeout=600), build.stderr.read()
    interrupted = err.splitlines()[-1:] == ["feedaxis: interrupted"] and "Traceback" not in err
    # 130, or killed by the SIGINT itself, which a shell reports as 130 too (128 + 2): seen
    # once in four CI runs under load after the one line was printed, never in 80 runs here
    assert code in (130, -signal.SIGINT) and interrupted or code == 0, (code, err)
    assert_complete_fmus(out, fmu_paths)
    assert not list(tmp_path.rglob(".*"))


INTERRUPT_ON_IMPORT = """
import os, signal, sys
class Interrupt:
    def find_spec(self, name, path=None, target=None):
        if name == {module!r}:
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, Interrupt())
sys.argv = ["feedaxis", *sys.argv[1:]]
from feedaxis.__main__ import run
run()
"""


@pytest.mark.parametrize("module", ["numpy", "scipy.optimize", "pyexpat", "matplotlib"])
def test_ctrl_c_during_the_start_up_imports_exits_130_with_one_line(tmp_path, module):
    """numpy and scipy.optimize load as the command starts, matplotlib where the report's
    first figure is drawn (the case's own report, its model empty). pyexpat loads within
    the start of xml.etree's C accelerator, which then fails as an ImportError that
    ElementTree ignores: the interrupt, swallowed there, is raised again before the
    command (it ran to its end and exited 0, seen under load as a lost SIGTERM)."""
    case = small_case(tmp_path / "c")
    result = subprocess.run([sys.executable, "-c", INTERRUPT_ON_IMPORT.format(module=module),
                             "report", str(case), "--out", str(tmp_path / "report.html")],
                            capture_output=True, text=True, timeout=300,
                            preexec_fn=default_sigint)
    assert (result.returncode, result.stderr) == (130, "feedaxis: interrupted\n")
    assert not (tmp_path / "report.html").exists()


# --- bounded time -----------------------------------------------------------------------

@pytest.mark.parametrize("time_s, row, words", [
    (np.linspace(0.0, 1e6, 21), "3", ["gap of 50000 s", "split the record at the gap"]),
    (np.arange(7313) * 1e4, "3", ["gap of 10000 s"]),
    (np.arange(0.0, 20000.0, 1.0), "10003", ["reaches 1e+08 steps", "split it"]),
])
def test_a_trace_the_loop_would_step_for_hours_is_refused_at_the_row(tmp_path, capsys, time_s,
                                                                     row, words):
    case = tracking_case(tmp_path / "t", time_s)
    assert_refused(capsys, ["compare", case], "tracking.csv", f"row {row}", "'time_s'", *words)


@pytest.mark.parametrize("options, words", [
    (["--step-ms", "20000", "--frequency-hz", "0.001", "--duration-s", "100"],
     ["--step-ms", "2e+05 steps", "at most 100000 between samples"]),
    (["--set", "NpidServo.time_step_s=1e-7", "--duration-s", "20"],
     ["duration_s", "2e+08 steps", "at most 1e+08"]),
])
def test_simulate_tracking_refuses_a_case_the_reader_would_refuse(tmp_path, capsys, fmu_paths,
                                                                   options, words):
    assert_refused(capsys, ["simulate", "tracking", tmp_path / "t", "--fmus",
                            fmu_folder(fmu_paths), *options], *words)
    assert not (tmp_path / "t").exists()


def test_samples_just_within_the_loops_budget_are_read(tmp_path):
    time_s = np.array([0.0, MAX_INTERVAL_STEPS * 1e-4, MAX_INTERVAL_STEPS * 1e-4 + 1e-3])
    assert read_case(tracking_case(tmp_path / "t", time_s)).tracking.time_s.size == 3


@pytest.mark.parametrize("text, read, words", [
    ("%\nN3620 A1 P1\nN3621 A1 P1\nN3622 A1 P2147483648\nN3623 A1 P1\nN3624 A1 P1000\n%\n",
     fanuc.read, ["line 4"]),
    ("%\nN3620 A1 P1\nN3621 A1 P1\nN3622 A1 P999999\nN3623 A1 P1\nN3624 A1 P1000\n%\n",
     fanuc.read, ["'3622'", "0 to 1023"]),
    ("$AA_ENC_COMP[0,0,X1]=0\n$AA_ENC_COMP_STEP[0,X1]=1e-9\n$AA_ENC_COMP_MIN[0,X1]=0\n"
     "$AA_ENC_COMP_MAX[0,X1]=37\n", siemens.read, ["line 2", "3.7e+10 points", "holds 4"]),
    ("$AA_ENC_COMP[0,0,X1]=0\n$AA_ENC_COMP_STEP[0,X1]=1\n$AA_ENC_COMP_MIN[0,X1]=5\n"
     "$AA_ENC_COMP_MAX[0,X1]=0\n", siemens.read, ["line 4", "must be above"]),
])
def test_controller_table_readers_bound_what_a_file_asks_for(text, read, words):
    with pytest.raises(LineError) as refused:
        read(text)
    assert all(word in str(refused.value) for word in words), str(refused.value)


# --- the right place and words ----------------------------------------------------------

def test_comp_table_from_one_target_names_the_users_case(tmp_path, capsys):
    case = small_case(tmp_path / "c", targets_mm=np.full(20, 5.0))
    err = assert_refused(capsys, ["comp-table", case, "--controller", "linuxcnc", "--out",
                                  tmp_path / "t.comp", "--from-measurement"],
                         str(case / "positioning.csv"), "at least two targets", "5 mm")
    assert "COMP_FILE" not in err and not (tmp_path / "t.comp").exists()


@pytest.mark.parametrize("separator", ["\u2028", "\x0c", "\x85", "\x1e"])
def test_a_comment_holding_a_unicode_line_separator_stays_one_line(tmp_path, separator):
    case = raw_case(tmp_path / "c", positioning=f"# laser {separator} 20 C\ntarget_mm,error_um\n"
                                                "0,1\n5,2\n")
    assert read_case(case).positioning.error_um.tolist() == [1.0, 2.0]


def test_axis_toml_lines_are_counted_as_toml_counts_them(tmp_path, capsys):
    case = raw_case(tmp_path / "c", "# axis \u2028 of mill 4\n[screw]\nlead_mm = 0\n",
                    "target_mm,error_um\n0,1\n5,2\n")
    assert_refused(capsys, ["compare", case], "axis.toml", "row 3", "screw.lead_mm")


def test_every_output_writer_stages_and_renames(tmp_path, monkeypatch):
    """A write that fails part-way (here the disk fills after the first bytes) leaves the
    old file as it was and no temporary one."""
    path = tmp_path / "report.html"
    path.write_text("old")

    def full(*args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(InputError, match="no space left on the device"):
        write_atomically(path, "new")
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == [path.name]


def test_the_import_benchmark_runs_at_a_tiny_size():
    """benchmarks/bench_import.py measures that import is linear in the rows (a list search
    per target made 10^5 rows take 60 s); here it must only finish."""
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_import.py"),
                             "--smoke"], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    assert "10x the rows takes" in result.stdout
