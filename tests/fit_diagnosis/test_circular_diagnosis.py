"""The loop on circular tests: each hidden effect named on its axis with its size, the
set-up never named, one direction undetermined.

Two sources of known answers: cases written from the closed forms (feedaxis.physics.circle)
with seeded noise, and cases simulated on the co-simulated machine with one FMU parameter
changed.
"""
import numpy as np
import pytest

from circular_cases import (CENTER_MM, FEED_MM_MIN, RADIUS_MM, circle_columns,
                            simulated_case, synthetic_case)
from feedaxis.diagnose import diagnose
from feedaxis.effects import Model
from feedaxis.effects.circular import circular_effects
from feedaxis.physics import circle

NOISE_UM = 0.1


def diagnosed(case):
    return diagnose(case, Model(), circular_effects(case.axis), kind="circular").to_json()


def named(diagnosis):
    return [(c["effect"], c["axis"], c["add"]) for c in diagnosis["candidates"]]


def value(diagnosis, add, parameter):
    candidate = next(c for c in diagnosis["candidates"] if c["add"] == add)
    return candidate["parameters"][parameter]["value"]


def setup_um(columns, seed):
    """A set-up: the pivot 3 µm off along X and -2 µm along Y, the radius 5 µm long, the
    instrument's length drifting 0.02 µm/s, white noise of NOISE_UM."""
    theta = np.radians(columns["angle_deg"])
    rng = np.random.default_rng(seed)
    return (5.0 + 3.0 * np.cos(theta) - 2.0 * np.sin(theta) + 0.02 * columns["time_s"]
            + rng.normal(0.0, NOISE_UM, theta.size))


SIGNATURES = {  # add name: (its closed form on (angle, direction), parameter, value)
    "backlash@Y": (lambda a, d: circle.backlash_um(a, d, 1, 3.0, RADIUS_MM), "backlash_um", 3.0),
    "backlash@X": (lambda a, d: circle.backlash_um(a, d, 0, -2.0, RADIUS_MM), "backlash_um",
                   -2.0),
    "squareness": (lambda a, d: circle.squareness_um(a, RADIUS_MM, 80.0), "squareness_urad",
                   80.0),
    "servo_mismatch": (lambda a, d: circle.lag_mismatch_um(a, d, FEED_MM_MIN / 60, 2e-3, 0.0),
                       "lag_difference_ms", 2.0),
    "lead_error@X": (lambda a, d: circle.radial_um(a, 0, 0.15 * circle.axis_positions_mm(
        a, RADIUS_MM, CENTER_MM, 0)), "slope_um_per_mm", 0.15),
    "reversal_spike@Y": (lambda a, d: circle.reversal_spike_um(a, d, 1, 1.5, 4.0), "height_um",
                         1.5),
}


@pytest.mark.parametrize("add", list(SIGNATURES))
def test_closed_form_named_on_its_axis_with_its_size(tmp_path, add):
    form, parameter, size = SIGNATURES[add]
    columns = circle_columns()
    deviation = form(columns["angle_deg"], columns["direction"]) + setup_um(columns, 7)
    diagnosis = diagnosed(synthetic_case(tmp_path / "c", deviation, columns))
    assert diagnosis["verdict"] == "missing_effect"
    assert diagnosis["candidates"][0]["add"] == add
    assert value(diagnosis, add, parameter) == pytest.approx(size, rel=0.02)
    effect, axis, _ = named(diagnosis)[0]
    assert axis == (add.split("@")[1] if "@" in add else None)
    assert effect == add.split("@")[0]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_set_up_alone_is_adequate(tmp_path, seed):
    """Centring offset, radius, drift and noise: the set-up's, never the machine's."""
    columns = circle_columns()
    diagnosis = diagnosed(synthetic_case(tmp_path / "c", setup_um(columns, seed), columns))
    assert diagnosis["verdict"] == "adequate" and not diagnosis["candidates"]


def test_one_direction_is_undetermined(tmp_path):
    """Squareness in one direction: the same sin 2θ as a servo mismatch; no effect named."""
    columns = circle_columns(directions=(1,))
    deviation = circle.squareness_um(columns["angle_deg"], RADIUS_MM, 80.0) + setup_um(columns, 4)
    diagnosis = diagnosed(synthetic_case(tmp_path / "c", deviation, columns))
    assert diagnosis["verdict"] == "undetermined" and not diagnosis["candidates"]
    assert "one direction" in diagnosis["undetermined_reason"]
    assert "both directions" in diagnosis["skipped"]["squareness"]


def test_unresolved_wavelength_is_passed_over(tmp_path):
    """Y's motor error repeats every 5 mm x 1.8° x 4 / 360° = 0.1 mm; 720 samples step up to
    0.17 mm along Y: passed over with the reason."""
    columns = circle_columns()
    diagnosis = diagnosed(synthetic_case(tmp_path / "c", setup_um(columns, 5), columns,
                                         motor=True))
    assert "does not resolve its 0.1 mm wavelength" in diagnosis["skipped"]["motor_step_error@Y"]


SIMULATED = {  # add name: (FMU parameters or squareness, parameter, value, relative tolerance)
    "backlash@Y": ({"parameters": {"Y_GeometricError": {"backlash_um": 4.0}}}, "backlash_um",
                   4.0, 0.01),
    "lead_error@X": ({"parameters": {"X_GeometricError": {"slope_um_per_mm": 0.2}}},
                     "slope_um_per_mm", 0.2, 0.01),
    "assembly_eccentricity@Y": ({"parameters": {"Y_GeometricError": {"eccentricity_cos_um": 1.0}}},
                                "cos_um", 1.0, 0.02),
    "squareness": ({"squareness_urad": 100.0}, "squareness_urad", 100.0, 0.01),
    "servo_mismatch": ({"parameters": {"X_NpidServo": {"kp_V_per_mm": 0.6}}},
                       "lag_difference_ms", 163.0 / 78020.0 * (1 / 0.6 - 1 / 0.8998) * 1e3, 0.01),
}


@pytest.mark.parametrize("add", list(SIMULATED))
def test_simulated_machine_effect_named_on_its_axis(tmp_path, fmu_paths, add):
    plan, parameter, size, tolerance = SIMULATED[add]
    case = simulated_case(tmp_path / "c", fmu_paths, noise_um=NOISE_UM, **plan)
    diagnosis = diagnosed(case)
    assert diagnosis["candidates"][0]["add"] == add
    assert value(diagnosis, add, parameter) == pytest.approx(size, rel=tolerance)


SERVO = {"controller": "pid", "kp_V_per_mm": 0.8998, "ki_V_per_mm_s": 0.0006077,
         "kd_V_s_per_mm": 0.005155, "force_constant_N_per_V": 100.0, "loop_step_s": 1e-4}


def test_loop_along_the_circle_is_the_cosimulated_machine(tmp_path, fmu_paths):
    """Where [servo] is given the model runs each axis's loop along the circle (the
    NpidServo kernel): on a noise-free case with 0.5 N of friction on X and X's kp at 0.6
    (a 40 µm lag against Y's 27 µm) it predicts the co-simulated radius to 0.01 µm."""
    from feedaxis import kinds
    from feedaxis.effects import Model

    case = simulated_case(tmp_path / "c", fmu_paths, servo=SERVO, parameters={
        "X_NpidServo": {"friction_N": 0.5, "kp_V_per_mm": 0.6}})
    measurement = kinds.kind("circular")(case)
    friction = circular_effects(case.axis)["coulomb_friction@X"]
    predicted_um = measurement.predictor(Model((friction,)))(
        {friction.name: {"friction_N": 0.5}})
    assert np.ptp(measurement.measured_um) > 10.0
    assert np.abs(measurement.measured_um - predicted_um).max() < 0.01


@pytest.mark.parametrize("axis, friction_N", [("X", 0.3), ("Y", 1.0)])
def test_friction_through_a_given_servo_is_named_with_its_size(tmp_path, fmu_paths, axis,
                                                               friction_N):
    """Coulomb friction through the loop of an axis whose [servo] is given: named as
    coulomb_friction on that axis with the force the case was simulated with, and no
    backlash invented for its reversal step; reversal spikes are not offered there."""
    case = simulated_case(tmp_path / "c", fmu_paths, noise_um=NOISE_UM, servo=SERVO,
                          parameters={f"{axis}_NpidServo": {"friction_N": friction_N}})
    diagnosis = diagnosed(case)
    assert named(diagnosis) == [("coulomb_friction", axis, f"coulomb_friction@{axis}")]
    assert value(diagnosis, f"coulomb_friction@{axis}", "friction_N") == pytest.approx(
        friction_N, rel=0.01)
    assert "servo loop" in diagnosis["skipped"][f"reversal_spike@{axis}"]


@pytest.mark.parametrize("parameters", [{}, {"X_NpidServo": {"kp_V_per_mm": 0.6}}])
def test_given_servos_alone_are_adequate(tmp_path, fmu_paths, parameters):
    """Nulls with [servo] given: equal loops, and unequal controllers as given (the 45°
    ellipse of their lags is predicted from the controllers, not named): adequate."""
    case = simulated_case(tmp_path / "c", fmu_paths, noise_um=NOISE_UM, servo=SERVO,
                          parameters=parameters, seed=3)
    diagnosis = diagnosed(case)
    assert diagnosis["verdict"] == "adequate", named(diagnosis)


def test_friction_without_a_servo_is_a_reversal_of_its_axis(tmp_path, fmu_paths):
    """Without [servo] the loop is not modelled: Coulomb friction F on X's P-loop trails X
    by F / (k_F kp) = 3.33 µm each way, a reversal of -6.67 µm of X; nothing named on Y,
    and coulomb_friction@X is not offered (it needs the controller)."""
    case = simulated_case(tmp_path / "c", fmu_paths, noise_um=NOISE_UM,
                          parameters={"X_NpidServo": {"friction_N": 0.3}})
    diagnosis = diagnosed(case)
    assert {axis for _, axis, _ in named(diagnosis)} == {"X"}
    assert value(diagnosis, "backlash@X", "backlash_um") == pytest.approx(
        -2 * 0.3 / 100.0 / 0.8998 * 1e3, rel=0.01)
    assert "needs [axes.X.servo]" in diagnosis["skipped"]["coulomb_friction@X"]


def test_compare_json_and_report_of_a_circular_case(tmp_path, capsys):
    """compare --json gives the ISO 230-4 figures as the ISO 230-2 ones are given; the
    report draws the polar trace with them; fit --json keys the parameters by ``add``."""
    import json

    from feedaxis.cli import main

    form, _, _ = SIGNATURES["backlash@Y"]
    columns = circle_columns()
    deviation = form(columns["angle_deg"], columns["direction"]) + setup_um(columns, 9)
    synthetic_case(tmp_path / "c", deviation, columns)
    assert main(["compare", str(tmp_path / "c"), "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)["figures"]
    assert set(figures) == {"G_um", "G_ccw_um", "G_cw_um", "H_um", "F_max_um", "F_min_um",
                            "G_mz_um", "G_ccw_mz_um", "G_cw_mz_um"}
    assert figures["G_um"]["center"] == "least squares, both paths"
    assert figures["G_mz_um"]["center"] == "minimum zone, both paths"
    for key in ("G_um", "G_ccw_um", "G_cw_um"):  # the minimum zone is the least G
        assert figures[key[:-3] + "_mz_um"]["measured_um"] <= figures[key]["measured_um"]
    assert all(set(f) == {"name", "measured_um", "residual_um", "explained", "center"}
               for f in figures.values())
    assert figures["H_um"]["measured_um"] == pytest.approx(3.0, abs=0.5)
    assert main(["fit", str(tmp_path / "c"), "--add", "backlash@Y", "--json",
                 "--out", str(tmp_path / "m.toml")]) == 0
    fitted = json.loads(capsys.readouterr().out)
    assert fitted["params"]["backlash@Y"]["backlash_um"] == pytest.approx(3.0, rel=0.02)
    assert set(fitted["artefacts"]["setup"]) == {"radius_um", "center_first_um",
                                                 "center_second_um", "drift_um_per_s"}
    assert fitted["artefacts"]["setup"]["center_first_um"] == pytest.approx(3.0, abs=0.05)
    assert main(["report", str(tmp_path / "c"), "--model", str(tmp_path / "m.toml"),
                 "--out", str(tmp_path / "r.html")]) == 0
    page = (tmp_path / "r.html").read_text()
    assert "polar trace of the circular test" in page and "ISO 230-4 figures" in page
