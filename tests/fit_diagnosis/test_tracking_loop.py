"""The loop on servo tracking data (issue 12): case format 1.1 [servo], tracking effects,
fit, diagnosis, compare, report, the NpidServo FMU against the fit, the scenario.

Cases come from tests/tracking_synthetic.py: a straightforward Runge-Kutta stepping of the
loop, independent of feedaxis.physics.servo, with seeded white plus AR(1) noise.
"""
import json
import math

import numpy as np
import pytest

from feedaxis.case import CaseError, read_case
from feedaxis.cli import main
from feedaxis.cosim.fmu_runner import run_fmu
from feedaxis.effects import CATALOG, Model
from feedaxis.fit import fit
from feedaxis.physics.servo import ServoParams, simulate
from feedaxis.diagnose import diagnose
from feedaxis.measurement import Tracking, servo_params
from test_seed_reproduction import TABLE1_PID_MM
from tracking_synthetic import (AXIS, SEED002, sine, step_loop, two_sines,
                                write_tracking_case)

PLANT = {"plant_gain_mm_per_Vs2": 70000.0, "plant_damping_per_s": 150.0,
         "plant_stiffness_per_s2": 250.0, "delay_s": 0.0015}
SERVO_PLANT = Model((CATALOG["servo_plant"],))


@pytest.fixture(scope="module")
def friction_run():
    """5 s of the exciting reference on PLANT with 1.5 N of hidden Coulomb friction."""
    return step_loop(two_sines, 5.0, plant=PLANT, friction_N=1.5)


def test_servo_table_reads_and_defaults_the_loop_step(tmp_path):
    axis = {**AXIS, "servo": {k: v for k, v in AXIS["servo"].items() if k != "loop_step_s"}}
    case = read_case(write_tracking_case(tmp_path / "c", step_loop(sine(1, 1), 0.05), 0, axis=axis))
    assert case.axis.servo["loop_step_s"] == 1e-4 and case.axis.servo["controller"] == "pid"
    assert servo_params(case.axis, Model()) == ServoParams(time_step_s=1e-4)


SERVO_AXIS = """name = "x"
[screw]
lead_mm = 1.0
[servo]
controller = "pid"
kp_V_per_mm = 1.0
ki_V_per_mm_s = 0.0
kd_V_s_per_mm = 0.0
force_constant_N_per_V = 100.0
"""


@pytest.mark.parametrize("old, new, row, column, message", [
    ('"pid"', '"pi"', "5", "servo.controller", "must be one of pid, npid"),
    ("kp_V_per_mm = 1.0", "kp_V_per_mm = -1", "6", "servo.kp_V_per_mm", "must be > 0"),
    ("kp_V_per_mm = 1.0", "gain = 1", "6", "servo.gain", "unknown or unit-less key"),
    ('"pid"', '"npid"', "4", "servo.ko_per_mm", "required for a npid controller"),
    ("force_constant_N_per_V = 100.0", "", "4", "servo.force_constant_N_per_V", "is required"),
])
def test_bad_servo_table_names_file_row_column_and_exits_2(tmp_path, capsys, old, new, row,
                                                           column, message):
    folder = tmp_path / "case"
    folder.mkdir()
    (folder / "axis.toml").write_text(SERVO_AXIS.replace(old, new))
    (folder / "tracking.csv").write_text("time_s,reference_mm,actual_mm\n0,0,0\n0.001,0,0\n")
    with pytest.raises(CaseError) as error:
        read_case(folder)
    assert (str(error.value.row), error.value.column) == (row, column)
    assert message in str(error.value) and "axis.toml" in str(error.value)
    assert main(["diagnose", str(folder)]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_table1_pid_figures_through_the_fits_simulation():
    """Anang et al. 2017 Table 1 PID column through the tracking measurement's prediction (the fit's
    path)."""
    for (frequency_hz, amplitude_mm), expected_mm in TABLE1_PID_MM.items():
        t = np.arange(int((1.0 + 2.0 / frequency_hz) / 1e-3)) * 1e-3
        reference = amplitude_mm * np.sin(2 * np.pi * frequency_hz * t)
        tracking = Tracking(_case_from_arrays(t, reference))
        predicted_um = tracking.predict_um(Model())
        last_two_periods = tracking.time_s > t[-1] - 2.0 / frequency_hz
        assert np.max(np.abs(predicted_um[last_two_periods])) * 1e-3 == pytest.approx(
            expected_mm, rel=0.02)


def _case_from_arrays(time_s, reference_mm):
    from feedaxis.case import Axis, Case
    from feedaxis.measurement.tracking import TrackingSamples
    return Case(None, Axis("x", {"lead_mm": 1.0}, {}, {**AXIS["servo"]}),
                {"tracking": TrackingSamples(time_s, reference_mm, reference_mm)})


def test_generator_and_fast_loop_agree(friction_run):
    """The independent Runge-Kutta stepping against the exact-ZOH kernel: same model."""
    time_s, reference_mm, position_mm = friction_run
    fast_mm = simulate(ServoParams(**PLANT, friction_N=1.5), time_s, reference_mm)
    assert np.max(np.abs(fast_mm - position_mm)) < 1e-6  # mm: 1 nm against ~30 µm of error


def test_npid_case_runs_the_nonlinear_loop(tmp_path):
    """An NPID [servo] table: the fit's loop against the generator's NPID (Anang et al. 2017 Eq. 8)."""
    npid = {"controller": "npid", "ko_per_mm": 6.0, "e_max_mm": 0.3}
    run = step_loop(sine(10.0, 0.7), 2.0, plant=PLANT, servo=npid, damping_N_s_per_mm=0.02)
    case = read_case(write_tracking_case(tmp_path / "c", run, 6,
                                         axis={**AXIS, "servo": {**AXIS["servo"], **npid}}))
    model = Model((CATALOG["servo_plant"], CATALOG["viscous_friction"]),
                  {"servo_plant": PLANT, "viscous_friction": {"damping_N_s_per_mm": 0.02}})
    assert servo_params(case.axis, model).npid
    tracking = Tracking(case)
    predicted_mm = tracking.reference_mm + tracking.predict_um(model) * 1e-3
    assert np.max(np.abs(predicted_mm - run[2][tracking.index])) < 1e-6


def test_fmu_and_fit_agree(loaded_fmus):
    """NpidServo FMU (plain-Python kernel) and the fit's compiled simulation, same inputs."""
    h, n = 1e-3, 3000
    t = np.arange(1, n + 1) * h
    reference = 10 * np.sin(2 * np.pi * 0.7 * t)
    force = 20 * np.sin(2 * np.pi * 37.0 * (t - h))
    parameters = {**PLANT, "friction_N": 2.0, "damping_N_s_per_mm": 0.03, "nonlinear": True}
    result = run_fmu(loaded_fmus["NpidServo"], h, n,
                     {"position_ref_mm": reference, "disturbance_N": force}, parameters,
                     ("position_mm",))
    # run_fmu starts at rest on reference[0] and applies input k over step k: as samples,
    # the interval ending at time (k+1)h is driven toward reference[k] under force[k].
    time_s = np.arange(n + 1) * h
    fitted_mm = simulate(ServoParams(**parameters), time_s,
                         np.concatenate(([reference[0]], reference)),
                         np.concatenate(([0.0], force)))[1:]
    assert np.max(np.abs(result["position_mm"] - fitted_mm)) < 1e-9


def test_hidden_friction_is_named_first_then_adequate(tmp_path, friction_run):
    case = read_case(write_tracking_case(tmp_path / "c", friction_run, 1))
    found = diagnose(case, SERVO_PLANT)
    assert found.verdict == "missing_effect"
    assert found.candidates[0].effect == "coulomb_friction"
    fitted = fit(SERVO_PLANT + CATALOG["coulomb_friction"], case)
    assert fitted.params()["coulomb_friction"]["friction_N"] == pytest.approx(1.5, rel=0.10)
    assert diagnose(case, fitted.model).verdict == "adequate"


def test_null_stays_adequate_over_20_seeds(tmp_path):
    """No effect, no structure: the false-alarm rate of the whole diagnosis on 20 seeds."""
    run = step_loop(two_sines, 2.0, plant=PLANT)
    verdicts = [diagnose(read_case(write_tracking_case(tmp_path / f"n{seed}", run, seed)),
                         SERVO_PLANT).verdict for seed in range(20)]
    assert verdicts == ["adequate"] * 20


def test_unknown_periodic_force_is_described_at_its_frequency(tmp_path):
    force_hz = 62.5  # 2 teeth at 1875 rpm
    run = step_loop(sine(10.0, 0.4), 4.0, plant=PLANT,
                    force_N=lambda t: 3.0 * math.sin(2 * math.pi * force_hz * t))
    found = diagnose(read_case(write_tracking_case(tmp_path / "c", run, 2)), SERVO_PLANT)
    assert found.verdict == "unexplained"
    periodic = found.unexplained[0]
    assert periodic.kind == "periodic"
    assert periodic.frequency_hz == pytest.approx(force_hz, rel=0.02)
    report = periodic.to_json()
    assert set(report) >= {"kind", "frequency_hz", "start_s", "end_s", "amplitude_um", "evidence"}
    assert report["end_s"] == 4.0  # a force lasting the record: no window


def test_plant_is_recovered_from_an_exciting_run_and_a_smooth_sine_says_what_it_cannot_fix(
        tmp_path):
    exciting = fit(SERVO_PLANT, read_case(write_tracking_case(
        tmp_path / "e", step_loop(two_sines, 5.0, plant=PLANT), 3)))
    for name, value in PLANT.items():
        fitted = exciting.params()["servo_plant"][name]
        sigma = exciting.uncertainties["servo_plant"][name]
        assert fitted == pytest.approx(value, rel=0.1)  # the delay to ±6 % (1 sigma)
        assert abs(fitted - value) < 4 * sigma
    # only the caveat every such reference carries: a recording delay would move the plant
    assert all("measurement delay" in why for why in exciting.undetermined.values())

    def smooth_sine(t):  # started gently: no transient, one frequency
        ramp = 0.5 - 0.5 * math.cos(math.pi * min(t, 2.0) / 2.0)
        return 10 * math.sin(2 * math.pi * 0.4 * t) * ramp

    single = fit(SERVO_PLANT, read_case(write_tracking_case(
        tmp_path / "s", step_loop(smooth_sine, 5.0, plant=PLANT), 3)))
    assert single.undetermined, "a single smooth sine cannot fix four plant parameters"
    for name in PLANT:
        assert (single.uncertainties["servo_plant"][name]
                > 10 * exciting.uncertainties["servo_plant"][name])


def test_cli_loop_on_a_tracking_case(tmp_path, capsys, friction_run):
    folder = str(write_tracking_case(tmp_path / "c", friction_run, 4))
    model = tmp_path / "m.toml"
    assert main(["diagnose", folder, "--json"]) == 0
    named = [c["effect"] for c in json.loads(capsys.readouterr().out)["candidates"]]
    assert named == ["servo_plant", "coulomb_friction"]  # the plant differs from Anang et al. 2017's
    assert main(["fit", folder, "--add", "servo_plant", "--add", "coulomb_friction",
                 "--out", str(model), "--json"]) == 0
    fitted = json.loads(capsys.readouterr().out)
    assert fitted["rms_after_um"] < 0.1 * fitted["rms_before_um"]
    assert main(["compare", folder, "--model", str(model), "--json"]) == 0
    comparison = json.loads(capsys.readouterr().out)
    maximum = comparison["max_tracking_error_mm"]
    assert maximum["predicted"] == pytest.approx(maximum["measured"], rel=0.01)
    assert main(["report", folder, "--model", str(model), "--out", str(tmp_path / "r.html")]) == 0
    page = (tmp_path / "r.html").read_text()
    assert page.count("<img") == 5 and "coulomb_friction" in page


def test_scenario_with_hidden_friction_closes_the_loop(tmp_path, capsys, fmu_paths):
    """simulate tracking --set NpidServo.friction_N=1 -> diagnose names it, fit finds 1 N."""
    out = str(tmp_path / "run")
    fmus = str(next(iter(fmu_paths.values())).parent)
    assert main(["simulate", "tracking", out, "--duration-s", "3", "--set",
                 "NpidServo.friction_N=1", "--fmus", fmus]) == 0
    assert read_case(out).axis.servo["kp_V_per_mm"] == AXIS["servo"]["kp_V_per_mm"]
    capsys.readouterr()
    assert main(["diagnose", out, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["candidates"][0]["effect"] == "coulomb_friction"
    assert main(["fit", out, "--add", "coulomb_friction", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["params"]["coulomb_friction"]["friction_N"] == \
        pytest.approx(1.0, rel=1e-6)
