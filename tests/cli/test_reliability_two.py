"""Issue 36: uncertainty that means something on small tests, no command that destroys its
input, SIGTERM as clean as Ctrl-C, no exit 1 on a broken file. One test per failure the
issue lists, with its inputs, in its order; then the round trip of every file the project
writes through every command that reads it.
"""
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

from feedaxis.case import read_case, write_case
from feedaxis.cli import main
from feedaxis.comptable import CONTROLLERS
from feedaxis.cosim import fmu_cache
from feedaxis.cosim.fmu_interface import check_fmu
from feedaxis.cosim.sweep.specs import model_draws, normal_factor
from feedaxis.effects import CATALOG, load_model
from feedaxis.errors import InputError
from feedaxis.examples import write_seed001_case
from feedaxis.fmu_build import FMU_NAMES
from feedaxis.output import write_atomically
from feedaxis.uncertainty.evaluation import evaluate
from test_bad_input import run

FEEDAXIS = [sys.executable, "-m", "feedaxis"]
TARGETS_MM = (0.0, 50.0, 100.0, 150.0, 200.0)
# the numerical tolerance (µm) each test asks of the adaptive procedure, per runs
TOLERANCE_UM = {2: 2.0, 3: 0.2, 5: 0.2}


def runs_case(folder, runs, seed=1):
    """5 targets over 200 mm, both directions, ``runs`` runs: a lead slope of 0.01 µm/mm,
    1 µm of backlash, 0.5 µm of Gaussian repeatability."""
    rng = np.random.default_rng(seed)
    rows = [(t, d, r) for r in range(1, runs + 1) for d in (1.0, -1.0) for t in TARGETS_MM]
    target, direction, run_ = (np.array(c) for c in zip(*rows))
    error = 0.01 * target + (direction < 0) + rng.normal(0.0, 0.5, target.size)
    return write_case(folder, {"name": f"{runs} runs", "screw": {"lead_mm": 5.0}},
                      positioning={"target_mm": target, "direction": direction,
                                   "run": run_, "error_um": error})


def console(*argv, **kwargs):
    """The console script in a fresh process: (exit code, stdout, stderr)."""
    result = subprocess.run([*FEEDAXIS, *map(str, argv)], capture_output=True, text=True,
                            timeout=600, **kwargs)
    return result.returncode, result.stdout, result.stderr


def hidden(folder):
    """The hidden entries (staging files and folders) in ``folder``."""
    return sorted(p.name for p in Path(folder).iterdir() if p.name.startswith("."))


# --- 1. a metrology result without meaning ----------------------------------------------

@pytest.mark.parametrize("runs", [2, 3, 5])
def test_uncertainty_intervals_are_stable_over_5_seeds_and_u_only_where_it_exists(
        tmp_path, runs):
    case = read_case(runs_case(tmp_path / "c", runs))
    tolerance = TOLERANCE_UM[runs]
    ends, results = [], []
    for seed in range(5):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = evaluate(case, tolerance_um=tolerance, seed=seed)
        results.append(result)
        ends.append([f["coverage_interval_um"] for f in result.figures.values()])
        said = [str(w.message) for w in caught]
        assert any(f"rests on {runs} runs" in m for m in said) == (runs < 5), said
    ends = np.array(ends)
    # each end is within T of its limit (JCGM 101 §7.9.4: 2 s <= T); 5 seeds within 2 T
    assert np.all(np.abs(ends - np.median(ends, axis=0)) <= 2 * tolerance), ends
    for result in results:
        assert result.adaptive.stabilised
        u = [f["standard_uncertainty_um"] for f in result.figures.values()]
        mean = [f["mean_um"] for f in result.figures.values()]
        if runs <= 3:  # ν = n - 1 <= 2: the t distribution has no variance
            assert u == [None] * len(u) and result.moments == (
                () if runs == 2 else ("mean",))
            assert all(m is None for m in mean) == (runs == 2)
            assert all(c["share"] is None for f in result.figures.values()
                       for c in f["contributions"].values())
        else:
            assert all(v > 0 for v in u)


def test_uncertainty_of_2_runs_prints_no_u_and_says_why(tmp_path, capsys):
    case = runs_case(tmp_path / "c", 2)
    code, out, err = run(capsys, "uncertainty", case, "--trials", 2000, "--seed", 3)
    assert code == 0, err
    assert "note: the uncertainty of every figure rests on 2 runs" in out
    assert "has no mean and no variance" in out
    figure_lines = [line for line in out.splitlines() if line.startswith("accuracy A ")]
    assert figure_lines and "n/a" in figure_lines[0] and "e+" not in figure_lines[0]
    code, out, _ = run(capsys, "uncertainty", case, "--trials", 2000, "--seed", 3, "--json")
    payload = json.loads(out)
    assert payload["figures"]["A_um"]["standard_uncertainty_um"] is None
    assert payload["moments"] == {"mean": False, "standard_uncertainty": False}


# --- 2. a documented workflow refused ---------------------------------------------------

def test_the_covariance_a_3_effect_fit_writes_is_drawn(tmp_path, capsys):
    case = write_seed001_case(tmp_path / "case")
    code, _, err = run(capsys, "fit", case, "--add", "lead_error", "--add",
                       "assembly_eccentricity", "--add", "motor_step_error", "--out",
                       tmp_path / "m.toml")
    assert code == 0, err
    draws = model_draws(load_model(tmp_path / "m.toml", CATALOG), seed=0)
    assert np.all(np.isfinite(draws.factor))


def test_covariance_checks_judge_on_the_correlation_scale():
    sigma = np.array([1e3, 1e-9])  # parameters of very different units
    correlation = np.array([[1.0, 0.3], [0.3, 1.0]])
    covariance = correlation * np.outer(sigma, sigma)
    noisy = covariance.copy()
    noisy[0, 1] *= 1 + 1e-9  # round-off of the fit's own arithmetic
    factor = normal_factor(noisy, "--from-model")
    assert np.allclose(factor @ factor.T, covariance, rtol=1e-8, atol=0)
    zero_to_round_off = np.diag([1.0, 1.0])
    zero_to_round_off[0, 1], zero_to_round_off[1, 0] = 1e-22, 1.00001e-22
    normal_factor(zero_to_round_off, "--from-model")
    for bad, words in (([[1.0, 0.5], [0.4, 1.0]], "symmetric"),
                       ([[1.0, 2.0], [2.0, 1.0]], "positive semi-definite")):
        with pytest.raises(InputError, match=words):
            normal_factor(np.array(bad), "--from-model")


# --- 3. commands that destroy their input -----------------------------------------------

@pytest.mark.parametrize("argv", [
    ["fit", "{case}", "--add", "lead_error", "--out", "{case}/positioning.csv"],
    ["report", "{case}", "--out", "{case}/axis.toml"],
    ["comp-table", "{case}", "--controller", "linuxcnc", "--from-measurement", "--out",
     "{case}/positioning.csv"],
    ["comp-table", "{case}", "--controller", "linuxcnc", "--from-measurement", "--out",
     "{link}"],
    ["uncertainty", "{case}", "--trials", "1000", "--html", "{case}/../c/positioning.csv"],
])
def test_out_resolving_to_an_input_is_refused_before_any_work(tmp_path, capsys, argv):
    case = runs_case(tmp_path / "c", 5)
    (tmp_path / "link.txt").symlink_to(case / "positioning.csv")
    before = {p.name: p.read_bytes() for p in case.iterdir()}
    argv = [a.format(case=case, link=tmp_path / "link.txt") for a in argv]
    code, _, err = run(capsys, *argv)
    assert code == 2 and "an input of this command" in err and err.count("\n") == 1, err
    assert {p.name: p.read_bytes() for p in case.iterdir()} == before


def test_a_hard_link_to_an_input_is_refused_as_out(tmp_path, capsys):
    case = runs_case(tmp_path / "c", 5)
    os.link(case / "axis.toml", tmp_path / "hard.toml")
    code, _, err = run(capsys, "fit", case, "--add", "lead_error", "--out",
                       tmp_path / "hard.toml")
    assert code == 2 and "an input of this command" in err


def test_a_case_file_linking_outside_the_case_is_refused_without_echoing_it(tmp_path,
                                                                             capsys):
    case = runs_case(tmp_path / "c", 5)
    secret = tmp_path / "secret.txt"
    secret.write_text("the first line of someone's private file\n")
    (case / "positioning.csv").unlink()
    (case / "positioning.csv").symlink_to(secret)
    code, out, err = run(capsys, "compare", case)
    assert code == 2 and "outside the case folder" in err and "--follow-links" in err
    assert "private file" not in out + err
    code, _, err = run(capsys, "compare", case, "--follow-links")
    assert code == 2 and "private file" in err  # read when asked: not a case file


def test_a_link_inside_the_case_is_read(tmp_path, capsys):
    case = runs_case(tmp_path / "c", 5)
    os.replace(case / "positioning.csv", case / "data.csv")
    (case / "positioning.csv").symlink_to("data.csv")
    assert run(capsys, "compare", case)[0] == 0


@pytest.mark.parametrize("controller", sorted(CONTROLLERS))
def test_an_axis_id_with_a_newline_is_refused_by_every_controller(tmp_path, capsys,
                                                                   controller):
    case = runs_case(tmp_path / "c", 5)
    out = tmp_path / "table.txt"
    axis_id = f"{CONTROLLERS[controller].default_axis_id}\nM30"
    code, _, err = run(capsys, "comp-table", case, "--controller", controller,
                       "--from-measurement", "--axis-id", axis_id, "--out", out)
    assert code == 2 and "--axis-id" in err and not out.exists(), err


# --- 4. SIGTERM is not Ctrl-C -----------------------------------------------------------

def wait_for(condition, timeout_s=300.0):
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def wait_for_cpu(process, seconds):
    """Wait until ``process`` has used ``seconds`` of CPU (user + system, from
    /proc/PID/stat) or has ended: a point in its own work however loaded the machine is;
    where there is no /proc, half a second on the wall clock."""
    stat = Path(f"/proc/{process.pid}/stat")
    if not stat.exists():
        time.sleep(0.5)
        return

    def used_s():
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # gone: it has ended
            return float("inf")
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    wait_for(lambda: process.poll() is not None or used_s() >= seconds)


def test_sigterm_during_demo_exits_143_and_leaves_no_staging_folder(tmp_path):
    out = tmp_path / "demo"
    demo = subprocess.Popen([*FEEDAXIS, "demo", "--out", str(out)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for(lambda: hidden(tmp_path) or demo.poll() is not None)
    demo.send_signal(signal.SIGTERM)
    _, err = demo.communicate(timeout=120)
    assert demo.returncode == 143, err
    assert err.strip().splitlines()[-1] == "feedaxis: interrupted (SIGTERM)", err
    assert hidden(tmp_path) == [] and not out.exists()


def test_sigterm_during_build_fmus_leaves_whole_fmus_and_no_temporary_folder(tmp_path):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    out = tmp_path / "fmus"
    build = subprocess.Popen([*FEEDAXIS, "build-fmus", "--out", str(out)], cwd=tmp_path,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env={**os.environ, "TMPDIR": str(scratch)})
    wait_for(lambda: any(scratch.iterdir()) or build.poll() is not None)
    build.send_signal(signal.SIGTERM)
    _, err = build.communicate(timeout=120)
    assert build.returncode in (143, 0), err
    assert list(scratch.iterdir()) == []
    assert not out.exists() or hidden(out) == []
    for path in out.glob("*.fmu") if out.exists() else ():
        check_fmu(path, path.stem)


def test_sigterm_during_sweep_keeps_the_finished_trials_and_says_so(tmp_path, fmu_paths):
    out = tmp_path / "sweep"
    argv = ["sweep", "iso230", str(out), "--vary", "GeometricError.backlash_um=uniform(0,5)",
            "--trials", "400", "--workers", "0", "--targets", "3", "--runs", "1",
            "--fmus", str(next(iter(fmu_paths.values())).parent)]
    sweep = subprocess.Popen([*FEEDAXIS, *argv], cwd=tmp_path, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    wait_for(lambda: (out / ".partial" / "plan.json").exists() or sweep.poll() is not None)
    time.sleep(3.0)
    sweep.send_signal(signal.SIGTERM)
    _, err = sweep.communicate(timeout=300)
    assert sweep.returncode == 143, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("feedaxis: interrupted: ") and "(SIGTERM)" in last, err
    kept = int(last.split("interrupted: ")[1].split(" of ")[0])
    import pyarrow.parquet as pq

    assert pq.read_table(out / "trials.parquet").num_rows == kept
    assert len(list((out / ".partial").glob("part-*.parquet"))) >= (kept > 0)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_stop_a_fit_as_ctrl_c_does(tmp_path, signum):
    case = write_seed001_case(tmp_path / "case")
    fit = subprocess.Popen([*FEEDAXIS, "fit", str(case), "--add", "lead_error", "--add",
                            "assembly_eccentricity", "--out", str(tmp_path / "m.toml")],
                           cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
    # after the handler (0.05 s), within the imports or the fit (0.75 s of CPU in all):
    # keyed to the child's own CPU time, so a loaded machine cannot delay the signal past
    # the fit's end (a 0.5 s wall-clock sleep could)
    wait_for_cpu(fit, 0.2)
    fit.send_signal(signum)
    _, err = fit.communicate(timeout=300)
    name = signal.Signals(signum).name
    assert fit.returncode == 128 + signum, err
    assert err.strip().splitlines()[-1] == f"feedaxis: interrupted ({name})", err
    assert not (tmp_path / "m.toml").exists() and hidden(tmp_path) == []


def test_a_stale_staging_folder_of_a_killed_run_is_removed_and_an_old_one_reported(tmp_path):
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    stale = tmp_path / f".model.toml-{gone}-abcd1234"
    stale.mkdir()
    (stale / "half").write_text("x")
    mine = tmp_path / f".model.toml-{os.getpid()}-efgh5678"
    mine.mkdir()
    older = tmp_path / ".model.toml-zz9_zz9z"
    older.mkdir()
    with pytest.warns(UserWarning, match="an earlier run that was killed"):
        write_atomically(tmp_path / "model.toml", "x = 1\n")
    assert not stale.exists() and mine.exists() and older.exists()


# --- 5. exit 1 on broken files ----------------------------------------------------------

@pytest.mark.parametrize("damage", ["truncated", "empty"])
def test_a_broken_fmu_in_the_cache_is_rebuilt(user_fmu_cache, fmu_paths, monkeypatch,
                                               damage):
    victim = user_fmu_cache / "GeometricError.fmu"
    data = victim.read_bytes()
    victim.write_bytes(data[:len(data) // 2] if damage == "truncated" else b"")
    built = []

    def build(folder, standalone=False, fmi=2):  # the real build: test_fmus.py, test_fmi3.py
        built.append(folder)
        for path in fmu_paths.values():
            shutil.copy2(path, Path(folder) / path.name)

    monkeypatch.setattr(fmu_cache, "build_fmus", build)
    paths = fmu_cache.fmu_paths()
    assert built and paths["GeometricError"].read_bytes() == \
        fmu_paths["GeometricError"].read_bytes()
    fmu_cache.fmu_paths()
    assert len(built) == 1  # intact now: not built again


def rewritten_fmu(source, target, change):
    """``source`` copied to ``target`` with ``change(name, data) -> data`` on its members."""
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(target, "w") as new:
        for item in old.infolist():
            new.writestr(item, change(item.filename, old.read(item)))


@pytest.mark.parametrize("change, words", [
    (lambda name, data: b"<fmiModelDescription" if name == "modelDescription.xml" else data,
     "modelDescription.xml cannot be read"),
    (lambda name, data: data.replace(b'name="error_um"', b'name="error_xx"')
     if name == "modelDescription.xml" else data, "the output error_um"),
    (lambda name, data: b"\x7fELF broken" if name.endswith(".so") else data,
     "shared library does not load"),
])
def test_a_broken_fmu_in_fmus_is_refused_naming_it(tmp_path, capsys, fmu_paths, change,
                                                   words):
    folder = tmp_path / "fmus"
    folder.mkdir()
    for name, path in fmu_paths.items():
        if name == "GeometricError":
            rewritten_fmu(path, folder / path.name, change)
        else:
            shutil.copy2(path, folder / path.name)
    code, _, err = run(capsys, "simulate", "iso230", tmp_path / "out", "--targets", 2,
                       "--runs", 1, "--fmus", folder)
    assert code == 2 and "GeometricError.fmu" in err and words in err, err
    assert not (tmp_path / "out").exists()


def test_a_truncated_partial_sweep_file_is_refused_naming_it(tmp_path, capsys, fmu_paths):
    out = tmp_path / "sweep"
    argv = ["sweep", "iso230", out, "--vary", "GeometricError.backlash_um=uniform(0,5)",
            "--trials", 2, "--workers", 0, "--targets", 2, "--runs", 1,
            "--fmus", next(iter(fmu_paths.values())).parent]
    # an interrupted sweep: its plan and the part file of its first trial ...
    from feedaxis.cosim import sweep as sweep_module

    stop_after = sweep_module.Store.add

    def interrupt(store, results, axis):
        stop_after(store, results, axis)
        raise KeyboardInterrupt

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(sweep_module.Store, "add", interrupt)
        assert run(capsys, *argv)[0] == 130
    part = next((out / ".partial").glob("part-*.parquet"))
    part.write_bytes(part.read_bytes()[:40])  # ... truncated
    code, _, err = run(capsys, *argv, "--resume")
    assert code == 2 and part.name in err and "damaged" in err, err


@pytest.mark.parametrize("budget, words", [
    ('[device_calibration]\ndistribution = "normal"\nexpanded_ppm = 1e300\n'
     "coverage_factor = 2\n", "expanded_ppm"),
    ("[eve]\nhalf_width_um = 1e308\n", "half_width_um"),
    ('[device_calibration]\ndistribution = "normal"\nexpanded_ppm = 0.5\n'
     "coverage_factor = 1e-320\n", "coverage_factor"),
])
@pytest.mark.parametrize("html", [False, True])
def test_a_budget_beyond_any_laser_is_refused_at_its_key(tmp_path, capsys, budget, words,
                                                         html):
    case = runs_case(tmp_path / "c", 5)
    (tmp_path / "b.toml").write_text(budget)
    page = tmp_path / "page.html"
    code, _, err = run(capsys, "uncertainty", case, "--budget", tmp_path / "b.toml",
                       "--trials", 1000, *(["--html", page] if html else []))
    assert code == 2 and "b.toml" in err and words in err, err
    assert not page.exists()


# --- 6. outputs the project itself then refuses -----------------------------------------

@pytest.mark.parametrize("setting, words", [
    ("GeometricError.offset_um=1e300", "--set: the simulated case would not be readable "
                                       "(positioning.csv, row 2, column 'error_um'"),
    ("ThermalScrew.expansion_per_K=1e308", "ThermalScrew.expansion_per_K: 1e+308 is beyond "
                                           "any physical axis")])
def test_simulate_refuses_a_case_compare_would_refuse(tmp_path, capsys, fmu_paths, setting,
                                                      words):
    out = tmp_path / "sim"
    code, _, err = run(capsys, "simulate", "iso230", out, "--targets", 2, "--runs", 1,
                       "--set", setting, "--fmus", next(iter(fmu_paths.values())).parent)
    assert code == 2 and words in err, err
    assert not out.exists() and hidden(tmp_path) == []


@pytest.mark.parametrize("spacing", ["1e300", "250", "nan", "1e-9"])
def test_comp_table_refuses_a_spacing_the_controller_cannot_hold(tmp_path, capsys, spacing):
    case = runs_case(tmp_path / "c", 5)
    out = tmp_path / "t.txt"
    code, _, err = run(capsys, "comp-table", case, "--controller", "mach4",
                       "--from-measurement", "--spacing-mm", spacing, "--out", out)
    assert code == 2 and "--spacing-mm" in err and not out.exists(), err


def test_pooled_duplicates_and_uneven_runs_are_said(tmp_path, capsys):
    case = runs_case(tmp_path / "c", 3)
    lines = (case / "positioning.csv").read_text().splitlines()
    # drop target 200 mm's third run in + and repeat two samples of run 1
    kept = [line for line in lines if not line.startswith(("200.0,1.0,3.0", "200,1,3"))]
    (case / "positioning.csv").write_text("\n".join(kept + lines[1:3]) + "\n")
    code, out, err = run(capsys, "compare", case)
    assert code == 0, err
    assert "2 samples repeat the target, direction and run of another" in out
    assert "uneven runs in +" in out


# --- what the writers write, the readers read -------------------------------------------

def test_every_file_written_is_read_by_the_commands_that_read_it(tmp_path, capsys,
                                                                 fmu_paths):
    fmus = next(iter(fmu_paths.values())).parent
    case = write_seed001_case(tmp_path / "case")
    model = tmp_path / "m.toml"
    assert run(capsys, "fit", case, "--add", "lead_error", "--add", "assembly_eccentricity",
               "--add", "motor_step_error", "--out", model)[0] == 0
    code, _, err = run(capsys, "sweep", "iso230", tmp_path / "sweep", "--from-model", model,
                       "--axis", case, "--trials", 2, "--workers", 0, "--targets", 2,
                       "--runs", 1, "--fmus", fmus)
    assert code == 0, err
    simulated = tmp_path / "sim"
    code, _, err = run(capsys, "simulate", "iso230", simulated, "--targets", 3, "--runs", 2,
                       "--model", model, "--axis", case, "--fmus", fmus)
    assert code == 0, err
    for command in (["compare", simulated], ["fit", simulated, "--add", "lead_error"],
                    ["uncertainty", simulated, "--trials", 1000]):
        code, _, err = run(capsys, *command)
        assert code == 0, (command, err)
    for name, controller in CONTROLLERS.items():
        out = tmp_path / f"table-{name}.txt"
        code, _, err = run(capsys, "comp-table", case, "--controller", name, "--model", model,
                           "--out", out, "--force")
        assert code == 0, (name, err)
        table = controller.read(out.read_text(encoding="utf-8"), str(out))
        assert table.size >= 2


def _raises(error):
    def raising(*args, **kwargs):
        raise error
    return raising


def _import_error_from_an_interrupt():
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as stopped:
        try:
            raise ImportError("initialization failed") from stopped
        except ImportError as error:
            return error


def test_an_interrupt_an_extensions_import_turned_into_an_import_error_is_a_stop(
        monkeypatch, capsys):
    """A stop signal inside a C extension's module initialisation reaches the command as
    ImportError("initialization failed") raised from the KeyboardInterrupt (pybind11's
    modules): the stop's exit and line, not an internal error; an ImportError of its own
    stays one."""
    from feedaxis import cli, stop

    monkeypatch.setattr(cli, "available_effects", _raises(_import_error_from_an_interrupt()))
    assert cli.main(["compare", "case"]) == stop.exit_code()
    assert capsys.readouterr().err.strip().splitlines()[-1].startswith("feedaxis: interrupted")
    monkeypatch.setattr(cli, "available_effects", _raises(ImportError("no module")))
    assert cli.main(["compare", "case"]) == 1
    assert "internal error" in capsys.readouterr().err
