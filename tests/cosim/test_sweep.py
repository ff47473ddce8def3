"""Sweeps: the same file from any number of Dask workers and after a resume, known answers
(backlash grid -> ISO reversal B, a linear effect's analytic band), bad specs refused."""
import importlib.util
import json
import re
import signal
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy import stats

from feedaxis.cli import main
from feedaxis.cosim.scenarios import iso230_targets
from feedaxis.cosim.sweep import (SweepInterrupted, parquet_bytes, read_sweep, sweep,
                                  sweep_metadata)
from feedaxis.cosim.sweep.specs import design, model_draws, parse_spec
from feedaxis.effects import CATALOG, FitRecord, Model
from feedaxis.errors import InputError
from feedaxis.examples import write_seed001_case

TRACKING = {"frequency_hz": 1.0, "amplitude_mm": 5.0, "duration_s": 1.2, "step_ms": 2.0}
FRICTION = ["NpidServo.friction_N=uniform(0,2)", "NpidServo.kp_V_per_mm=normal(0.9,0.05)"]
SHORT_ISO = ("--targets", "2", "--spacing-mm", "2", "--runs", "1", "--dwell-s", "0.2")
# a screw that does not heat (tests/cosim/test_scenarios.py): the deviation is then the geometry
QUIET_AXIS = ("--set", "ThermalScrew.k3_W_per_mm_min=0", "--set", "ThermalScrew.k4_W_per_mm_min=0")


@pytest.fixture(scope="module")
def fmu_dir(fmu_paths):
    return str(next(iter(fmu_paths.values())).parent)


def file_bytes(folder):
    return (folder / "trials.parquet").read_bytes()


def test_dask_workers_give_the_in_process_file_bit_for_bit(fmu_dir, tmp_path):
    """A LocalCluster of two worker processes (through the API, then the command line's
    --scheduler), then of one, gives the trials.parquet bytes of the plain loop in this
    process."""
    distributed = pytest.importorskip("distributed")
    here = sweep("tracking", FRICTION, trials=6, seed=5, workers=0, fmus=fmu_dir, **TRACKING)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        two = sweep("tracking", FRICTION, trials=6, seed=5, client=client, fmus=fmu_dir,
                    **TRACKING)
        assert main(["sweep", "tracking", str(tmp_path / "cli"), *sum(
            (["--vary", v] for v in FRICTION), []), "--trials", "6", "--seed", "5",
            "--frequency-hz", "1", "--amplitude-mm", "5", "--duration-s", "1.2",
            "--step-ms", "2", "--scheduler", cluster.scheduler_address, "--fmus", fmu_dir]) == 0
        cluster.scale(1)
        deadline = time.monotonic() + 60
        while len(client.scheduler_info()["workers"]) > 1 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert len(client.scheduler_info()["workers"]) == 1
        one = sweep("tracking", FRICTION, trials=6, seed=5, client=client, fmus=fmu_dir,
                    **TRACKING)
    assert here.num_rows == 6 and here.column("error").null_count == 6
    assert parquet_bytes(two) == parquet_bytes(here)
    assert parquet_bytes(one) == parquet_bytes(here)
    assert (tmp_path / "cli" / "trials.parquet").read_bytes() == parquet_bytes(here)
    friction = here.column("NpidServo.friction_N").to_numpy()
    error_mm = here.column("max_tracking_error_mm").to_numpy()
    assert np.all((friction >= 0) & (friction <= 2)) and np.ptp(error_mm) > 0
    assert len(here.column("series")[0]) > 100  # the tracking error's band


def test_an_interrupted_sweep_resumed_gives_the_uninterrupted_file(tmp_path, fmu_dir):
    def press_ctrl_c(done, total):
        if done == 2:
            signal.raise_signal(signal.SIGINT)

    with pytest.raises(SweepInterrupted, match="interrupted: 2 of 5 trials kept .* --resume"):
        sweep("tracking", FRICTION, trials=5, seed=2, out=tmp_path / "cut", workers=0,
              fmus=fmu_dir, progress=press_ctrl_c, **TRACKING)
    kept = pq.read_table(tmp_path / "cut" / "trials.parquet")
    assert kept.column("trial").to_pylist() == [0, 1]
    assert json.loads((tmp_path / "cut" / "summary.json").read_text())["complete"] is False
    with pytest.raises(InputError, match="different sweep; it differs in seed"):
        sweep("tracking", FRICTION, trials=5, seed=3, out=tmp_path / "cut", workers=0,
              fmus=fmu_dir, resume=True, **TRACKING)
    ran = []
    sweep("tracking", FRICTION, trials=5, seed=2, out=tmp_path / "cut", workers=0,
          fmus=fmu_dir, resume=True, progress=lambda done, total: ran.append(done), **TRACKING)
    assert ran == [3, 4, 5]  # only the missing trials ran
    sweep("tracking", FRICTION, trials=5, seed=2, out=tmp_path / "whole", workers=0,
          fmus=fmu_dir, **TRACKING)
    assert file_bytes(tmp_path / "cut") == file_bytes(tmp_path / "whole")
    assert not (tmp_path / "cut" / ".partial").exists()


def test_a_backlash_grid_gives_the_iso_reversal_of_each_trial(tmp_path, fmu_dir, capsys):
    """B = max |x̄↑ - x̄↓| (ISO 230-2) equals the swept backlash within 0.02 µm, the
    noise-free tolerance of the iso230 scenario (tests/cosim/test_scenarios.py)."""
    out = tmp_path / "backlash"
    assert main(["sweep", "iso230", str(out), "--vary", "GeometricError.backlash_um=grid(0,10,3)",
                 *SHORT_ISO, *QUIET_AXIS, "--workers", "0", "--fmus", fmu_dir, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    table = read_sweep(out)  # the documented way back (docs/sweep.md)
    assert table.equals(pq.read_table(out / "trials.parquet"))
    with pytest.raises(InputError, match="not a sweep folder"):
        read_sweep(tmp_path)
    swept = table.column("GeometricError.backlash_um").to_numpy()
    np.testing.assert_array_equal(swept, [0.0, 5.0, 10.0])
    np.testing.assert_allclose(table.column("B_um").to_numpy(), swept, atol=0.02)
    assert summary["sensitivities"]["B_um"]["inputs"]["GeometricError.backlash_um"]["spearman"] \
        == pytest.approx(1.0)
    assert summary["bands"]["group"][:2] == ["+", "+"]  # mean deviations per direction
    assert (out / "report.html").read_text().count("<img") >= 3
    assert "sweep of iso230: 3 of 3 trials" in (out / "summary.txt").read_text()


@pytest.fixture(scope="module")
def lead_model(tmp_path_factory):
    """lead_error fitted (say) to 0.25 µm + -0.5 µm/mm with a correlated covariance, saved
    with its [fit] table; the axis of the bundled Liu 2023 case."""
    folder = tmp_path_factory.mktemp("lead")
    write_seed001_case(folder / "case")
    covariance = np.array([[0.04, -0.006], [-0.006, 0.0025]])
    record = FitRecord(("lead_error.offset_um", "lead_error.slope_um_per_mm"), covariance, {},
                       100, 0.05)
    model = Model([CATALOG["lead_error"]],
                  {"lead_error": {"offset_um": 0.25, "slope_um_per_mm": -0.5}}, record)
    (folder / "lead.toml").write_text(model.to_toml())
    return folder, covariance


def test_propagation_through_a_linear_effect_gives_the_analytic_band(lead_model, fmu_dir):
    """Each trial's mean deviation is b + a·x of its drawn (b, a) within 0.02 µm, and the
    band's variance at each target is x̃ C x̃ᵀ (x̃ = [1, x]): its sample variance over 60
    trials lies in the chi-square interval of 99.9 % (which leaves out the band of the same
    variances without their correlation), its mean within 3.3 standard errors."""
    folder, covariance = lead_model
    targets_mm = iso230_targets(2, 2.0)
    trials = 60
    table = sweep("iso230", (), trials=trials, seed=11, workers=0, fmus=fmu_dir,
                  from_model=folder / "lead.toml", axis=folder / "case",
                  targets_mm=targets_mm, runs=1, dwell_s=0.2)
    band_x = np.array(sweep_metadata(table)["series"]["x"])
    series = np.vstack(table.column("series").to_pylist())
    offset = table.column("lead_error.offset_um").to_numpy()[:, None]
    slope = table.column("lead_error.slope_um_per_mm").to_numpy()[:, None]
    np.testing.assert_allclose(series, offset + slope * band_x, atol=0.02)
    design_x = np.column_stack([np.ones_like(band_x), band_x])
    variance = np.einsum("ij,jk,ik->i", design_x, covariance, design_x)
    low, high = stats.chi2.ppf([0.0005, 0.9995], trials - 1) / (trials - 1)
    ratio = np.var(series, axis=0, ddof=1) / variance
    assert np.all((low < ratio) & (ratio < high)), ratio
    mean_error = np.mean(series, axis=0) - (0.25 - 0.5 * band_x)
    assert np.all(np.abs(mean_error) < 3.3 * np.sqrt(variance / trials))


def test_undetermined_parameters_are_refused_or_held(lead_model):
    folder, covariance = lead_model
    record = FitRecord(("lead_error.offset_um", "lead_error.slope_um_per_mm"), covariance,
                       {"lead_error.slope_um_per_mm": "one target only"}, 3, 0.1)
    model = Model([CATALOG["lead_error"]],
                  {"lead_error": {"offset_um": 0.25, "slope_um_per_mm": -0.5}}, record)
    with pytest.raises(InputError, match="could not determine lead_error.slope_um_per_mm "
                                         r"\(one target only\).*--hold-undetermined"):
        model_draws(model, 0)
    held = model_draws(model, 0, hold_undetermined=True)
    assert held.keys == ("lead_error.offset_um",)
    values, _ = held.values(4)
    assert held.model_at(values).values["lead_error"]["slope_um_per_mm"] == -0.5
    with pytest.raises(InputError, match=r"has no \[fit\] table"):
        model_draws(model.with_record(None), 0)


@pytest.mark.parametrize("spec, words", [
    ("NpidServo.friction=uniform(0,2)", ["has no Real parameter friction", "friction_N"]),
    ("NpidServo.friction_N=poisson(3)", ["unknown distribution 'poisson'", "uniform(...)"]),
    ("NpidServo.friction_N=uniform(-1,2)", ["below NpidServo.friction_N's minimum 0"]),
    ("NpidServo.friction_N=normal(0.5,1)", ["drawn values reach", "minimum 0"]),
    ("Spindle.speed_rpm=uniform(0,1)", ["no component Spindle"]),
    ("NpidServo.friction_N=uniform(2,1)", ["needs a < b"]),
])
def test_bad_vary_specs_are_refused_before_any_trial(tmp_path, fmu_dir, capsys, spec, words):
    out = tmp_path / "bad"
    assert main(["sweep", "tracking", str(out), "--vary", spec, "--trials", "20",
                 "--workers", "0", "--fmus", fmu_dir]) == 2
    message = capsys.readouterr().err
    assert f"--vary {spec}" in message
    for word in words:
        assert word in message
    assert not out.exists()


def test_trial_values_depend_on_the_seed_and_the_trial_only():
    grid_and_draws = design(["A.x=grid(0,1,3)", "B.y=uniform(0,1)",
                             "C.u,C.v=mvnormal([0,1],[[1,0.5],[0.5,1]])"], 4, seed=9)
    assert grid_and_draws.trials == 12
    assert [grid_and_draws.values(k)["A.x"] for k in (0, 3, 4, 11)] == [0.0, 0.0, 0.5, 1.0]
    again = design(["A.x=grid(0,1,3)", "B.y=uniform(0,1)",
                    "C.u,C.v=mvnormal([0,1],[[1,0.5],[0.5,1]])"], 4, seed=9)
    assert [again.values(k) for k in (11, 2, 7)] == [grid_and_draws.values(k) for k in (11, 2, 7)]
    draws = np.array([list(design(["C.u,C.v=mvnormal([0,1],[[1,0.5],[0.5,1]])"], 4000,
                                  seed=1).values(k).values()) for k in range(2000)])
    assert np.corrcoef(draws.T)[0, 1] == pytest.approx(0.5, abs=0.07)  # 4 standard errors
    with pytest.raises(InputError, match="not positive semi-definite"):
        parse_spec("C.u,C.v=mvnormal([0,1],[[1,2],[2,1]])")
    with pytest.raises(InputError, match="grid sets its own count"):
        design(["A.x=grid(0,1,3)"], 5, seed=0)


def test_the_docs_api_snippet_runs(user_fmu_cache, capsys):
    page = (Path(__file__).resolve().parents[2] / "docs" / "sweep.md").read_text()
    snippet = re.search(r"<!-- snippet: sweep-api -->\n```python\n(.*?)```", page, re.S).group(1)
    exec(compile(snippet, "docs/sweep.md snippet", "exec"), {"__name__": "__main__"})
    printed = capsys.readouterr().out
    assert "'B_um'" in printed and len(printed.splitlines()) == 4


def test_the_sweep_benchmark_runs_at_a_tiny_size(user_fmu_cache, capsys):
    """benchmarks/bench_sweep.py --smoke: every path it times runs and it prints the
    overhead, the speed-up and the cluster size for 10^6 trials."""
    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_sweep.py"
    spec = importlib.util.spec_from_file_location("bench_sweep", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    bench.main(["--smoke"])
    printed = capsys.readouterr().out
    assert re.search(r"distributed overhead per trial .*: wall [-+]\d+\.\d %, CPU [-+]\d+\.\d %",
                     printed)
    assert re.search(r"throughput of 2 workers / 1 worker: \d+\.\d\dx", printed)
    assert re.search(r"10\^6 such trials in one hour: \d+ worker cores", printed)


def test_a_cluster_pays_only_for_enough_work():
    """Known answers of the cost model: n trials of t s take n·t here against
    CLUSTER_START_S + n·t / cores on a local cluster."""
    from feedaxis.cosim.sweep.run import CLUSTER_START_S, cluster_pays

    assert not cluster_pays(1, 0.2, 2)
    assert not cluster_pays(1000, 0.2, 1)  # one core: a cluster never gains
    even = 2 * CLUSTER_START_S  # n·t at which two workers break even
    assert not cluster_pays(100, 0.999 * even / 100, 2)
    assert cluster_pays(100, 1.001 * even / 100, 2)


def test_small_sweeps_run_here_and_say_so(fmu_dir, monkeypatch):
    """The default workers: a sweep too small for a cluster runs in this process (nothing
    reaches Dask), says so, and gives the table of --workers 0; with a free cluster start
    the trials after the first go to the cluster."""
    import feedaxis.cosim.sweep.run as sweep_module

    def no_cluster(*args):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(sweep_module.os, "cpu_count", lambda: 2)
    monkeypatch.setattr(sweep_module, "_run_on_dask", no_cluster)
    here = sweep("tracking", FRICTION, trials=3, seed=5, workers=0, fmus=fmu_dir, **TRACKING)
    said = []
    default = sweep("tracking", FRICTION, trials=3, seed=5, fmus=fmu_dir, echo=said.append,
                    **TRACKING)
    assert default.equals(here)
    assert len(said) == 1 and said[0].startswith("ran in this process: 3 trial(s)")

    handed = []

    def cluster_here(plan, job, remaining, finished, *where):
        handed.extend(remaining)
        sweep_module._run_here(plan, job, remaining, finished)

    monkeypatch.setattr(sweep_module, "CLUSTER_START_S", 0.0)
    monkeypatch.setattr(sweep_module, "_run_on_dask", cluster_here)
    said.clear()
    switched = sweep("tracking", FRICTION, trials=3, seed=5, fmus=fmu_dir, echo=said.append,
                     **TRACKING)
    assert handed == [1, 2] and not said and switched.equals(here)


def test_one_trial_has_no_spread_to_draw_and_imports_no_matplotlib(fmu_dir, tmp_path):
    """A sweep of one trial writes its figures in the table and no figure (a histogram of
    one value, a band of one curve): the command then never imports matplotlib."""
    import subprocess
    import sys

    out = tmp_path / "one"
    script = (f"import sys; from feedaxis.cli import main; "
              f"code = main(['sweep', 'tracking', {str(out)!r}, '--vary', {FRICTION[0]!r}, "
              f"'--trials', '1', '--duration-s', '1.2', '--step-ms', '2', '--workers', '0', "
              f"'--fmus', {fmu_dir!r}]); print('matplotlib' in sys.modules); sys.exit(code)")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "False"
    page = (out / "report.html").read_text()
    assert "<img" not in page
    assert "1 finished trial: no spread to draw" in page
    assert "max_tracking_error_mm" in page
