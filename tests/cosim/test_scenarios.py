"""Scenarios on the co-simulated axis: cases that load back, Anang et al. 2017 Table 1, Ctrl-C, CLI."""
import signal

import numpy as np
import pytest

from feedaxis.case import read_case
from feedaxis.cli import main
from feedaxis.cosim.master import Master
from feedaxis.cosim.scenarios import (MeasurementNoise, ScenarioInterrupted, iso230_targets,
                                      simulate_iso230, simulate_tracking)
from feedaxis.cosim.system import default_axis
from feedaxis.physics import geometry, motor, mounting
from test_seed_reproduction import TABLE1_PID_MM

# A screw that does not heat; the positioning scenarios' default servo (a0 = 0: the plant
# integrates) has no static error: the deviation is then the geometry.
QUIET_AXIS = ("--set", "ThermalScrew.k3_W_per_mm_min=0", "--set", "ThermalScrew.k4_W_per_mm_min=0")


@pytest.fixture(scope="module")
def fmu_dir(fmu_paths):
    return str(next(iter(fmu_paths.values())).parent)


@pytest.fixture(scope="module")
def master(fmu_paths):
    with Master(default_axis(), fmu_paths) as running:
        yield running


def simulate(*args):
    return main(["simulate", *map(str, args)])


def test_iso230_case_loads_back_with_the_iso_layout(tmp_path, fmu_dir):
    """The deviation at each target is the geometry of the physics within 0.02 µm.

    0.02 µm: after the 0.2 s dwell the servo is within ~10 nm of the target, and the motor
    error (period 20 µm of travel) turns that into up to 0.01 µm.
    """
    out = tmp_path / "iso"
    assert simulate("iso230", out, "--targets", 3, "--spacing-mm", 2, "--dwell-s", 0.2,
                    "--fmus", fmu_dir, *QUIET_AXIS) == 0
    case = read_case(out)
    p = case.positioning
    assert case.axis.lead_mm == 1.0 and case.axis.motor["error_period_steps"] == 10
    assert p.time_s is not None and np.all(np.diff(p.time_s) > 0)  # the clock of the drift
    targets = iso230_targets(3, 2.0)
    np.testing.assert_allclose(np.unique(p.target_mm), targets)
    for target in targets:
        for direction in (1, -1):
            runs = p.run[(p.target_mm == target) & (p.direction == direction)]
            assert sorted(runs) == [1, 2, 3, 4, 5]
    sag_table = geometry.gravity_sag_table(0.8, 0.034, 7800.0, 2.1e11, "fixed-free")
    sag_um = geometry.gravity_sag_error_um(mounting.screw_coordinate_m(p.target_mm, -141.0),
                                           sag_table)
    geometric_um = [geometry.transmission_error_um(x, d, 1.0, 0.2515, -0.5084, 0.2005, 0.1504,
                                                   0.0, s)
                    for x, d, s in zip(p.target_mm, p.direction, sag_um)]
    motor_um = motor.motor_step_error_um(p.target_mm, 1.0, 0.72, 10, (0.08, 0.0), (0.06, 0.0))
    np.testing.assert_allclose(p.error_um, geometric_um + motor_um, atol=0.02)
    assert_duty_is_the_motion(case)


def assert_duty_is_the_motion(case):
    """duty.csv holds the motion simulated: every sample's time lies within it, and the
    duty puts the axis at the sample's target then (data-format.md: time_s counts from the
    duty's first row)."""
    assert case.is_thermal and case.positioning.time_s[-1] <= case.duty.end_s
    segments = case.duty.segments
    starts_s = np.array([segment.start_s for segment in segments])
    for time_s, target_mm in zip(case.positioning.time_s, case.positioning.target_mm):
        segment = segments[np.searchsorted(starts_s, time_s, side="left") - 1]
        assert segment.nut_position_mm(time_s) == pytest.approx(target_mm, abs=1e-9)


def test_thermal_case_has_duty_and_timed_samples_that_drift_with_heat(tmp_path, fmu_dir):
    duty = tmp_path / "duty.csv"
    duty.write_text("start_s,duration_s,feed_mm_min,from_mm,to_mm,ambient_C\n"
                    "0,20,9000,0,300,20\n20,10,0,0,0,21\n")
    out = tmp_path / "thermal"
    assert simulate("thermal", out, "--duty", duty, "--targets", "50,250", "--every-s", 10,
                    "--dwell-s", 0.2, "--fmus", fmu_dir, "--step-ms", 2) == 0
    case = read_case(out)
    assert case.is_thermal
    p = case.positioning
    assert p.size == 4 * 2 and list(p.run) == [1, 1, 2, 2, 3, 3, 4, 4]
    assert np.all(np.diff(p.time_s) > 0) and p.time_s[-1] <= case.duty.end_s
    np.testing.assert_allclose(p.ambient_C, [20, 20, 20, 20, 20, 20, 21, 21])
    at_250 = p.error_um[p.target_mm == 250.0]
    assert np.all(np.diff(at_250[:3]) > 0.05), "the heated screw must push the error up"


@pytest.mark.parametrize("row", sorted(TABLE1_PID_MM))
def test_tracking_pid_reproduces_seed002_table1_through_the_axis(tmp_path, master, row):
    frequency_hz, amplitude_mm = row
    summary = simulate_tracking(tmp_path / "tracking", master, frequency_hz, amplitude_mm,
                                1.0 + 2.0 / frequency_hz)
    assert summary["max_tracking_error_mm"] == pytest.approx(TABLE1_PID_MM[row], rel=0.02)
    tracking = read_case(tmp_path / "tracking").tracking
    settled = tracking.time_s > 1.0
    written_mm = np.abs(tracking.reference_mm - tracking.actual_mm)[settled]
    assert written_mm.max() == pytest.approx(summary["max_tracking_error_mm"], rel=1e-9)
    assert summary["rms_tracking_error_mm"] == pytest.approx(np.sqrt(np.mean(written_mm**2)))


def test_tracking_with_cutting_force_writes_the_disturbance(tmp_path, master):
    quiet = simulate_tracking(tmp_path / "quiet", master, 0.7, 10.0, 1.5)
    cutting = simulate_tracking(tmp_path / "cutting", master, 0.7, 10.0, 1.5,
                                spindle_rpm=1500, force_N=300.0)
    force = read_case(tmp_path / "cutting").tracking.disturbance_N
    assert 0 <= force.min() and force.max() == pytest.approx(300.0, rel=1e-3)
    assert cutting["max_tracking_error_mm"] != pytest.approx(quiet["max_tracking_error_mm"],
                                                             rel=1e-3)


def test_measurement_noise_is_added_to_the_measured_column_only(tmp_path, master):
    """The noisy case differs from the exact one by the seeded draws, in µm."""
    exact = simulate_tracking(tmp_path / "exact", master, 0.7, 10.0, 1.2)
    noisy = simulate_tracking(tmp_path / "noisy", master, 0.7, 10.0, 1.2,
                              noise=MeasurementNoise(0.5, seed=3))
    assert noisy["noise"] == {"sigma_um": 0.5, "seed": 3}
    assert noisy["max_tracking_error_mm"] == exact["max_tracking_error_mm"]
    exact_case = read_case(tmp_path / "exact").tracking
    noisy_case = read_case(tmp_path / "noisy").tracking
    np.testing.assert_array_equal(noisy_case.reference_mm, exact_case.reference_mm)
    added_um = 1e3 * (noisy_case.actual_mm - exact_case.actual_mm)
    draws = np.random.default_rng(3).normal(0.0, 0.5, added_um.size)
    np.testing.assert_allclose(added_um, draws, atol=1e-6)   # the CSV keeps 1e-9 mm


def test_ctrl_c_writes_the_samples_computed_so_far(tmp_path, master):
    def press_ctrl_c(done_steps, total_steps):
        if done_steps == 3000:
            signal.raise_signal(signal.SIGINT)

    with pytest.raises(ScenarioInterrupted, match=r"interrupted: \d+ of 30 samples written"):
        simulate_iso230(tmp_path / "partial", master, iso230_targets(3, 2.0), dwell_s=0.2,
                        progress=press_ctrl_c)
    partial = read_case(tmp_path / "partial")
    assert 0 < partial.positioning.size < 30
    assert partial.positioning.size % 6 == 0  # whole runs only: 3 targets x 2 directions
    runs = partial.positioning.size // 6
    assert partial.name == f"simulated ISO 230-2 test (interrupted: {runs} of 5 runs)"
    assert partial.duty.end_s == pytest.approx(partial.positioning.time_s[-1])
    assert_duty_is_the_motion(partial)


@pytest.mark.parametrize("args, message", [
    (("iso230", "{out}", "--targets", 1), "at least 2 targets"),
    (("iso230", "{out}", "--set", "NpidServo.gain=2"), "NpidServo: no parameter gain"),
    (("iso230", "{out}", "--set", "Spindle.rpm=2"), "no component 'Spindle'"),
    (("iso230", "{out}", "--set", "nonlinear"), "expected COMPONENT.PARAMETER=VALUE"),
    (("iso230", "{out}", "--thermal-step-s", 0.0015), "whole multiple of the macro step"),
    (("iso230", "{out}", "--model", "m.toml"), "--model: needs --axis"),
    (("tracking", "{out}", "--frequency-hz", -1), "frequency_hz: must be > 0"),
    (("tracking", "{out}", "--noise-um", -1), "--noise-um: must be a finite number >= 0"),
    (("thermal", "{out}", "--duty", "missing.csv", "--targets", "1"), "missing.csv: case file not found"),
    (("thermal", "{out}", "--duty", "{bad}", "--targets", "1"), "bad.csv, row 2, column 'duration_s'"),
    (("thermal", "{out}", "--duty", "{good}", "--targets", "1,x"), "--targets 1,x: expected"),
    (("tracking", "{existing}"), "already exists"),
])
def test_bad_input_exits_2_with_one_message_and_writes_nothing(tmp_path, capsys, fmu_dir, args,
                                                              message):
    (tmp_path / "bad.csv").write_text("start_s,duration_s,feed_mm_min,from_mm,to_mm\n"
                                      "0,-5,100,0,10\n")
    (tmp_path / "good.csv").write_text("start_s,duration_s,feed_mm_min,from_mm,to_mm\n"
                                       "0,5,100,0,10\n")
    (tmp_path / "existing").mkdir()
    paths = {"out": tmp_path / "out", "bad": tmp_path / "bad.csv",
             "good": tmp_path / "good.csv", "existing": tmp_path / "existing"}
    argv = [str(a).format(**paths) for a in args]
    assert simulate(*argv, "--fmus", fmu_dir) == 2
    error = capsys.readouterr().err
    assert message in error and error.count("\n") == 1
    assert not (tmp_path / "out").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv", "existing", "good.csv"]


def test_positioning_scenarios_default_to_a_type1_servo_that_set_overrides():
    from feedaxis.cosim.scenarios.positioning import _positioning_parameters
    assert _positioning_parameters(None)["NpidServo"] == {"plant_stiffness_per_s2": 0.0}
    published = {"NpidServo": {"plant_stiffness_per_s2": 193.3, "nonlinear": True}}
    assert _positioning_parameters(published) == published
