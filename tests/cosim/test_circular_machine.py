"""The co-simulated machine on a circle against the closed-form signatures of each error.

Each run differs from the machine with every effect off by one effect; the difference of
the recorded radii is that effect's signature, which must equal its closed form
(feedaxis.physics.circle). The servo runs are identical in both (the geometric errors are
kinematic), except for the lag mismatch, which changes a servo gain.
"""
import numpy as np
import pytest

from circular_cases import CENTER_MM, FEED_MM_MIN, RADIUS_MM, simulated_case
from feedaxis.iso230_4 import centring_basis
from feedaxis.physics import circle


@pytest.fixture(scope="module")
def runs(tmp_path_factory, fmu_paths):
    folder = tmp_path_factory.mktemp("machine")
    plans = {"neutral": {}, "backlash": {"parameters": {"Y_GeometricError": {"backlash_um": 4.0}}},
             "scale": {"parameters": {"X_GeometricError": {"slope_um_per_mm": 0.3}}},
             "squareness": {"squareness_urad": 150.0},
             "lag": {"parameters": {"X_NpidServo": {"kp_V_per_mm": 0.6}}}}
    return {name: simulated_case(folder / name, fmu_paths, samples_per_turn=720, **plan).circular
            for name, plan in plans.items()}


def difference(runs, name):
    base, run = runs["neutral"], runs[name]
    np.testing.assert_array_equal(base.angle_deg, run.angle_deg)
    return run.angle_deg, run.direction, run.deviation_um - base.deviation_um


def apart_from_centring(angle_deg, values):
    """``values`` with the radius and the centring offset (1, cos θ, sin θ) fitted out."""
    basis = centring_basis(angle_deg)
    return values - basis @ np.linalg.lstsq(basis, values, rcond=None)[0]


def lag_s(kp_V_per_mm=0.8998):
    """The lag of an axis's loop at a steady feed: the plant b / s(s + a1) needs the command
    u = a1 v / b, which the P action gives at the error a1 v / (b kp) (Anang et al. 2017's plant)."""
    return 163.0 / (78020.0 * kp_V_per_mm)


def test_backlash_steps_at_the_axis_reversals(runs):
    """Y's error ±B/2 enters the radius at the point's actual angle, which trails the
    commanded one by ω T (0.11°)."""
    angle, direction, signature = difference(runs, "backlash")
    lag_deg = np.degrees(FEED_MM_MIN / 60 / RADIUS_MM * lag_s())
    phi = circle.since_reversal_deg(angle, direction, 1)
    away = (phi > 3) & (phi < 177)                   # past the play and the servo's lag
    expected = circle.backlash_um(angle - direction * lag_deg, direction, 1, 4.0)
    np.testing.assert_allclose(signature[away], expected[away], atol=2e-4)
    # the step is B at the reversal points of Y (90°, 270°), nothing at those of X
    assert np.ptp(signature) == pytest.approx(4.0, rel=1e-3)


def lagged_deg(angle, direction):
    """The point's actual angle: the commanded one less ω T."""
    return angle - direction * np.degrees(FEED_MM_MIN / 60 / RADIUS_MM * lag_s())


def test_scale_mismatch_is_an_ellipse_along_the_axes(runs):
    """A lead slope s of X: R s / 2 cos 2θ about the centre (3 µm); exactly, the error
    s x along X at the point's actual angle, to 1e-4 µm."""
    angle, direction, signature = difference(runs, "scale")
    expected = circle.scale_mismatch_um(angle, RADIUS_MM, 0.3, 0.0)
    np.testing.assert_allclose(apart_from_centring(angle, signature),
                               apart_from_centring(angle, expected), atol=0.02 * 3.0)
    actual = lagged_deg(angle, direction)
    x_um = 0.3 * circle.axis_positions_mm(actual, RADIUS_MM, CENTER_MM, 0)
    np.testing.assert_allclose(signature, moved_radius_um(actual, x_um, 0), atol=1e-4)


def moved_radius_um(angle_deg, along_x_um, along_y_um):
    """The radius change (µm) of the point at ``angle_deg`` moved by the two (exactly)."""
    theta = np.radians(angle_deg)
    return (np.hypot(RADIUS_MM * np.cos(theta) + along_x_um * 1e-3,
                     RADIUS_MM * np.sin(theta) + along_y_um * 1e-3) - RADIUS_MM) * 1e3


def test_squareness_is_an_ellipse_at_45_degrees_both_ways(runs):
    """α of Y towards X: α R / 2 sin 2θ (1.5 µm), the same both ways; exactly, the table
    moves α y along X at the point's actual angle."""
    angle, direction, signature = difference(runs, "squareness")
    expected = circle.squareness_um(angle, RADIUS_MM, 150.0)
    np.testing.assert_allclose(apart_from_centring(angle, signature),
                               apart_from_centring(angle, expected), atol=0.02 * 1.5)
    actual = lagged_deg(angle, direction)
    along_x_um = 150e-6 * circle.axis_positions_mm(actual, RADIUS_MM, CENTER_MM, 1) * 1e3
    np.testing.assert_allclose(signature, moved_radius_um(actual, along_x_um, 0), atol=1e-4)


def test_lag_mismatch_flips_with_the_direction(runs):
    """X's loop at kp 0.6 V/mm lags ΔT = 163/78020 (1/0.6 - 1/0.8998) = 1.160 ms more
    than Y's (:func:`lag_s`)."""
    angle, direction, signature = difference(runs, "lag")
    expected = circle.lag_mismatch_um(angle, direction, FEED_MM_MIN / 60, lag_s(0.6), lag_s())
    column = np.sin(2 * np.radians(angle)) * direction
    fitted = np.linalg.lstsq(np.column_stack((centring_basis(angle), column)), signature,
                             rcond=None)[0][-1]
    assert fitted == pytest.approx(np.max(expected), rel=0.01)
    assert fitted == pytest.approx(FEED_MM_MIN / 60 * (lag_s(0.6) - lag_s()) / 2 * 1e3, rel=0.01)



def test_simulate_circular_takes_a_fitted_model(tmp_path, capsys):
    """``simulate circular --model`` sets the model's effects in the machine's FMUs, the
    same trace as their values given with --set; a servo_mismatch (no FMU parameter) is
    refused naming the model file."""
    import json

    from circular_cases import circle_columns, synthetic_case
    from feedaxis.cli import main

    case = synthetic_case(tmp_path / "c", np.zeros(720), circle_columns()).folder
    model = tmp_path / "m.toml"
    model.write_text('["backlash@Y"]\nbacklash_um = 4.0\nlag_deg = 0.0\n'
                     '["lead_error@X"]\nslope_um_per_mm = 0.2\n'
                     '[squareness]\nsquareness_urad = 50.0\n')
    common = ["--machine", str(case), "--samples-per-turn", "360", "--json"]
    assert main(["simulate", "circular", str(tmp_path / "a"), "--model", str(model),
                 *common]) == 0
    assert main(["simulate", "circular", str(tmp_path / "b"), "--squareness-urad", "50",
                 "--set", "Y_GeometricError.backlash_um=4", "--set",
                 "X_GeometricError.slope_um_per_mm=0.2", *common]) == 0
    capsys.readouterr()
    traces = [np.loadtxt(tmp_path / name / "circular.csv", delimiter=",", skiprows=1,
                         usecols=1) for name in ("a", "b")]
    assert np.ptp(traces[0]) > 4.0
    np.testing.assert_array_equal(traces[0], traces[1])
    model.write_text('[servo_mismatch]\nlag_difference_ms = 1.0\n')
    assert main(["simulate", "circular", str(tmp_path / "d"), "--model", str(model),
                 *common]) == 2
    error = json.loads(capsys.readouterr().out)
    assert error["column"] == "servo_mismatch" and not (tmp_path / "d").exists()
