"""Physics functions against independent answers: the paper's literal scheme, closed forms."""
import math

import numpy as np
import pytest
from scipy.integrate import quad

from feedaxis.errors import ParameterError
from feedaxis.physics import geometry, motor, mounting, scalar, servo, thermal


def literal_eq10_step(T, Ta, p, v, nut_center_m, dt):
    """Rong et al. 2023 Eq. 10 exactly as printed: whole cells, case by case (1-based n)."""
    N = p.n_cells
    r = p.conductivity_W_mK * dt / (p.density_kg_m3 * p.specific_heat_J_kgK * p.cell_length_m**2)
    src = 4 * dt / (np.pi * p.diameter_m**2 * p.density_kg_m3 * p.specific_heat_J_kgK)
    h = p.k1_W_m2K_per_mm_min * v + p.k2_W_m2K
    conv = 4 * h * dt / (p.density_kg_m3 * p.specific_heat_J_kgK * p.diameter_m)
    lo = (nut_center_m - p.nut_length_m / 2) / p.cell_length_m
    hi = (nut_center_m + p.nut_length_m / 2) / p.cell_length_m
    new = T.copy()
    for n in range(1, N + 1):
        i = n - 1
        if n == 1:
            new[i] = T[i] + r * (T[i + 1] - T[i]) + src * p.k3_W_per_mm_min * v / p.bearing_length_m
        elif n <= round(p.bearing_length_m / p.cell_length_m):
            new[i] = T[i] + r * (T[i + 1] + T[i - 1] - 2 * T[i]) + src * p.k3_W_per_mm_min * v / p.bearing_length_m
        elif lo < n - 1e-9 and n <= hi + 1e-9:
            new[i] = T[i] + r * (T[i + 1] + T[i - 1] - 2 * T[i]) + src * p.k4_W_per_mm_min * v / p.nut_length_m
        elif n == N:
            new[i] = T[i] + r * (T[i - 1] - T[i]) - conv * (1 + p.diameter_m / (4 * p.cell_length_m)) * (T[i] - Ta)
        else:
            new[i] = T[i] + r * (T[i + 1] + T[i - 1] - 2 * T[i]) - conv * (T[i] - Ta)
    return new


def test_thermal_step_is_the_papers_eq10_at_dt_0_1_s():
    params = thermal.ThermalScrewParams(nut_length_m=0.2)  # nut edges on cell boundaries
    nut_center_mm = 300.0 - 141.0  # 0.3 m from the fixed end
    ours = np.zeros(params.n_cells)
    literal = np.full(params.n_cells, 21.5)
    for _ in range(3000):
        ours = thermal.advance(params, ours, 0.1, nut_center_mm, 6000.0)
        literal = literal_eq10_step(literal, 21.5, params, 6000.0, 0.3, 0.1)
    assert ours.max() > 1.0
    np.testing.assert_allclose(ours, literal - 21.5, rtol=1e-10, atol=1e-12)


def test_thermal_large_steps_stay_stable_and_close():
    params = thermal.ThermalScrewParams()
    fine = coarse = np.zeros(params.n_cells)
    for _ in range(600):
        fine = thermal.advance(params, fine, 1.0, 100.0, 6000.0)
    coarse = thermal.advance(params, coarse, 600.0, 100.0, 6000.0)
    assert np.all(np.isfinite(coarse))
    np.testing.assert_allclose(coarse, fine, rtol=1e-9)


def test_thermal_error_sign_follows_fixed_end_side():
    negative = thermal.ThermalScrewParams(fixed_end_mm=-141.0)
    positive = thermal.ThermalScrewParams(fixed_end_mm=641.0)
    rise = np.linspace(2.0, 0.5, negative.n_cells)
    # P_f < 0: TE = TE_m(P_x - P_f) (Eq. 16); P_f > 0: TE = -TE_m(P_f - P_x) (Eq. 15)
    assert thermal.thermal_error_um(negative, rise, 200.0) == pytest.approx(
        thermal.screw_elongation_um(negative, rise, 0.341))
    assert thermal.thermal_error_um(positive, rise, 200.0) == pytest.approx(
        -thermal.screw_elongation_um(positive, rise, 0.441))


def test_npid_gain_at_e_max_is_the_papers_value():
    assert servo.npid_gain(0.3, 6.0, 0.3) == pytest.approx(3.1075, abs=1e-4)
    assert servo.npid_gain(-5.0, 6.0, 0.3) == servo.npid_gain(0.3, 6.0, 0.3)


def test_gravity_sag_matches_small_slope_integral():
    L, D, rho, E = 0.8, 0.034, 7800.0, 2.1e11
    q = rho * 9.80665 * np.pi * D**2 / 4
    EI = E * np.pi * D**4 / 64
    slope = lambda y: q * y * (3 * L**2 - 3 * L * y + y**2) / (6 * EI)  # cantilever w'(y)
    expected_um = -1e6 * quad(lambda y: slope(y) ** 2 / 2, 0.0, L)[0]
    table = geometry.gravity_sag_table(L, D, rho, E, "fixed-free")
    assert geometry.gravity_sag_error_um(L, table) == pytest.approx(expected_um, rel=1e-4)


def test_motor_error_period_of_seed001_motor():
    assert motor.motor_error_period_mm(1.0, 0.72, 10) == pytest.approx(0.002 * 10)
    y = np.array([0.0, 0.005, 0.02])
    np.testing.assert_allclose(motor.motor_step_error_um(y, 1.0, 0.72, 10, [0.1], [0.0]),
                               [0.1, 0.0, 0.1], atol=1e-12)


def test_backlash_reversal_is_iso_reversal_value():
    up = geometry.backlash_error_um(1, 3.0)
    down = geometry.backlash_error_um(-1, 3.0)
    assert up - down == pytest.approx(3.0)


def test_per_sample_thermal_error_equals_the_field_evaluated_row_by_row():
    params = thermal.ThermalScrewParams(fixed_end_mm=-141.0)
    fields = thermal.simulate_duty(params, thermal.table2_cycle(6000.0), [600.0, 3000.0, 9000.0])
    positions = np.array([0.0, 250.0, 640.0])
    per_sample = thermal.thermal_error_um(params, fields, positions)
    row_by_row = [thermal.thermal_error_um(params, field, x) for field, x in zip(fields, positions)]
    np.testing.assert_allclose(per_sample, row_by_row, rtol=1e-12)


@pytest.mark.parametrize("conductivity_W_mK", (566.3, 4000.0))
def test_closed_form_duty_equals_eq10_stepped_with_the_nut_moving(conductivity_W_mK):
    """simulate_duty (nut heat averaged over its path, closed form) against explicit_duty
    (Eq. 10 stepped at dt with the nut where its run puts it); λ = 4000 makes the
    stability limit set dt (0.044 s), with alternating modes in the closed form."""
    params = thermal.ThermalScrewParams(conductivity_W_mK=conductivity_W_mK)
    segments = thermal.table2_cycle(9000.0)
    times_s = np.arange(0.0, segments[-1].end_s, 600.0) + 3.0
    closed = thermal.simulate_duty(params, segments, times_s)
    stepped = thermal.explicit_duty(params, segments, times_s)
    position_mm = np.linspace(0.0, 500.0, times_s.size)
    closed_um = thermal.thermal_error_um(params, closed, position_mm)
    stepped_um = thermal.thermal_error_um(params, stepped, position_mm)
    assert np.max(np.abs(stepped_um)) > 20.0
    np.testing.assert_allclose(closed_um, stepped_um, atol=0.01)


def test_averaged_nut_heat_is_the_exact_path_mean():
    params = thermal.ThermalScrewParams()
    path_m = 0.141 + 0.5 * (np.arange(20000) + 0.5) / 20000
    mean = np.mean([thermal.nut_cells(params.cells, x) for x in path_m], axis=0)
    np.testing.assert_allclose(thermal.averaged_nut_cells(params, 0.141, 0.641), mean, atol=1e-6)
    assert thermal.averaged_nut_cells(params, 0.641, 0.141).sum() * params.cell_length_m \
        == pytest.approx(params.nut_length_m)


@pytest.mark.parametrize("plant", [(193.3, 163.0, 78020.0), (0.0, 0.0, 1.0), (0.0, 163.0, 1e9),
                                   (6642.25, 163.0, 78020.0), (1e6, 1e4, 1.0), (1e-3, 0.0, 78020.0)])
@pytest.mark.parametrize("duration_s", [1e-7, 1e-4, 1e-3, 1e-2])
def test_servo_discretisation_equals_scipy_expm(plant, duration_s):
    """The zero-order hold (Φ, Γ) without scipy.linalg (servo.expm, Taylor with scaling and
    squaring) equals scipy.linalg.expm of the augmented matrix with the plant's own input
    column: the plant of Anang et al. 2017, a double integrator, critical damping (a1² = 4 a0), stiff."""
    from scipy.linalg import expm
    stiffness, damping, gain = plant
    reference = expm(np.array([[0.0, 1.0, 0.0], [-stiffness, -damping, gain], [0.0, 0.0, 0.0]])
                     * duration_s)
    transition, late = servo._zoh(plant, duration_s)
    for ours, theirs in ((transition, reference[:2, :2]), (late[:, None], reference[:2, 2:])):
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=3e-12 * np.abs(theirs).max())


def test_servo_discretisation_of_a_double_integrator_is_exact():
    """ẍ = b·u held over τ: Φ = [[1, τ], [0, 1]], Γ = b·[τ²/2, τ] (no stiffness, no damping)."""
    tau = 1e-4
    transition, late = servo._zoh((0.0, 0.0, 78020.0), tau)
    np.testing.assert_allclose(transition, [[1.0, tau], [0.0, 1.0]], rtol=1e-15, atol=0)
    np.testing.assert_allclose(late, [78020.0 * tau**2 / 2, 78020.0 * tau], rtol=1e-15)


@pytest.mark.parametrize("settings", [{}, {"damping_N_s_per_mm": 0.3, "delay_s": 0.00125},
                                      {"friction_N": 1.0}, {"nonlinear": True}])
def test_servo_over_a_communication_step_equals_the_loop_stepped(settings):
    """A linear loop (PID, no Coulomb friction) advances by one propagator matrix per
    communication step; it equals the kernel stepped 0.1 ms at a time, with the delay line,
    a force, irregular intervals and a remainder carried. Nonlinear loops keep stepping."""
    params = servo.ServoParams(**settings)
    fast, stepped = servo.Servo(params, 1.0), servo.Servo(params, 1.0)
    stepped._propagators = None
    assert (fast._propagators is not None) == (not settings.get("nonlinear")
                                               and not settings.get("friction_N"))
    rng = np.random.default_rng(7)
    time_s = np.cumsum(rng.choice([1e-3, 1e-3, 2.5e-3, 0.4e-3], size=2000))
    reference_mm = 10.0 * np.sin(2 * np.pi * 0.7 * time_s)
    force_N = 50.0 * np.sin(2 * np.pi * 40.0 * time_s)
    duration_s = np.diff(time_s, prepend=0.0)
    for dt, ref, force in zip(duration_s, reference_mm, force_N):
        assert fast.advance(dt, ref, force) == pytest.approx(stepped.advance(dt, ref, force),
                                                            abs=1e-12)
        assert fast.velocity_mm_s == pytest.approx(stepped.velocity_mm_s, abs=1e-10)


@pytest.mark.parametrize("time_step_s", [1e-4, 3e-4, 7.3e-5])
def test_step_counts_compiled_equal_the_python_carry(time_step_s):
    """servo.step_counts (carry_steps compiled by numba) against carry_steps run by Python
    over irregular samples: the same internal steps per interval, remainders carried."""
    rng = np.random.default_rng(11)
    time_s = np.cumsum(rng.choice([1e-3, 1e-3, 2.5e-3, 0.4e-3, 0.05e-3], size=5000))
    python_counts = np.zeros(time_s.size, dtype=np.int64)
    servo.carry_steps(np.diff(time_s), time_step_s, python_counts)
    assert np.array_equal(servo.step_counts(time_s, time_step_s), python_counts)
    assert python_counts[0] == 0 and len(set(python_counts[1:])) > 3  # remainders carried


@pytest.mark.parametrize("settings", [{"nonlinear": True}, {"friction_N": 20.0},
                                      {"nonlinear": True, "friction_N": 5.0, "delay_s": 0.00125,
                                       "damping_N_s_per_mm": 0.3}, {}])
def test_compiled_servo_loop_equals_the_python_loop(compiled_servo_loop, settings):
    """run_loop compiled ahead of time (what the NpidServo FMU steps) against run_loop run
    by Python, over NPID, Coulomb friction, both with a fractional delay, and PID: the
    positions within 1e-12 mm, with irregular intervals, a force and remainders carried."""
    params = servo.ServoParams(**settings)
    compiled = servo.Servo(params, 1.0, loop=compiled_servo_loop)
    python = servo.Servo(params, 1.0)
    python._propagators = None  # the kernel stepped in Python, PID included
    rng = np.random.default_rng(3)
    time_s = np.cumsum(rng.choice([1e-3, 1e-3, 2.5e-3, 0.4e-3], size=3000))
    reference_mm = 2.0 * np.sin(2 * np.pi * 0.7 * time_s) + 0.25 * (time_s > 1.0)
    force_N = 50.0 * np.sin(2 * np.pi * 40.0 * time_s)
    duration_s = np.diff(time_s, prepend=0.0)
    positions_mm = np.array([(compiled.advance(dt, ref, force), python.advance(dt, ref, force))
                             for dt, ref, force in zip(duration_s, reference_mm, force_N)])
    assert np.max(np.abs(positions_mm[:, 0] - positions_mm[:, 1])) <= 1e-12
    assert np.ptp(positions_mm[:, 1]) > 3.0  # the loop moved: the comparison tests something
    assert compiled.velocity_mm_s == pytest.approx(python.velocity_mm_s, abs=1e-9)
    assert compiled.state()["loop"] == pytest.approx(python.state()["loop"], abs=1e-12)


@pytest.mark.parametrize("settings", [{}, {"friction_N": 1.0}])
def test_servo_state_saved_and_restored_mid_run_continues_the_same(settings):
    """state() of a propagated loop (vector form) restored into a new servo, and into one
    that steps the kernel, continues as the original did (FMU get/set state)."""
    params = servo.ServoParams(**settings)
    rng = np.random.default_rng(11)
    reference_mm = rng.uniform(-5.0, 5.0, 400)
    force_N = rng.normal(0.0, 20.0, 400)
    original = servo.Servo(params, 0.0)
    for ref, force in zip(reference_mm[:200], force_N[:200]):
        original.advance(1e-3, ref, force)
    saved = original.state()
    assert len(saved["loop"]) == servo.STATE_SIZE and len(saved["commands_V"]) == params.buffer_size
    restored, stepped = servo.Servo(params, 0.0), servo.Servo(params, 0.0)
    restored.restore(saved)
    stepped.restore(saved)
    stepped._propagators = None
    for ref, force in zip(reference_mm[200:], force_N[200:]):
        expected = original.advance(1e-3, ref, force)
        assert restored.advance(1e-3, ref, force) == expected
        assert stepped.advance(1e-3, ref, force) == pytest.approx(expected, abs=1e-12)
    assert restored.state() == original.state()


def test_scalar_interp_equals_numpy_interp_bit_for_bit():
    """One float through the bisection on the table's lists gives np.interp's value: inside,
    at every node, at and beyond both ends, NaN."""
    rng = np.random.default_rng(3)
    grid = np.cumsum(rng.uniform(0.001, 0.01, 500))
    samples = scalar.table(grid, rng.normal(0.0, 1.0, 500))
    points = np.concatenate((rng.uniform(grid[0] - 0.1, grid[-1] + 0.1, 5000), grid,
                             [grid[0], grid[-1], -np.inf, np.inf]))
    for x in points.tolist():
        assert scalar.interp(x, samples) == np.interp(x, grid, samples.y)
    assert np.isnan(scalar.interp(float("nan"), samples))
    np.testing.assert_array_equal(scalar.interp(points, samples), np.interp(points, grid, samples.y))


@pytest.mark.parametrize("fixed_end_mm", (-141.0, 641.0))
def test_geometric_and_motor_errors_of_one_float_equal_the_array_path(fixed_end_mm):
    """The FMUs' scalar paths (math module, bisection, comparisons for the clip) against
    NumPy on arrays, at seeded random positions and directions (±1 and inside the play),
    the fixed end on either side: the same formula, so equal to 1e-12 µm."""
    rng = np.random.default_rng(5)
    position_mm = rng.uniform(-300.0, 900.0, 2000)
    direction = np.where(rng.random(2000) < 0.5, rng.choice([-1.0, 1.0], 2000),
                         rng.uniform(-1.5, 1.5, 2000))
    table = geometry.gravity_sag_table(0.8, 0.034, 7800.0, 2.1e11, "fixed-fixed")
    screw_m = mounting.screw_coordinate_m(position_mm, fixed_end_mm)
    sag_um = geometry.gravity_sag_error_um(screw_m, table)
    arrays_um = geometry.transmission_error_um(position_mm, direction, 5.0, 0.25, -0.5, 0.2,
                                               0.15, 3.0, sag_um)
    motor_um = motor.motor_error_um(position_mm, 0.02, (0.08, 0.01), (0.06, -0.02))
    for k, (x, d) in enumerate(zip(position_mm.tolist(), direction.tolist())):
        one_screw_m = mounting.screw_coordinate_m(x, fixed_end_mm)
        assert type(one_screw_m) is float and one_screw_m == screw_m[k]
        one_sag_um = geometry.gravity_sag_error_um(one_screw_m, table)
        assert type(one_sag_um) is float and one_sag_um == sag_um[k]
        one_um = geometry.transmission_error_um(x, d, 5.0, 0.25, -0.5, 0.2, 0.15, 3.0, one_sag_um)
        assert type(one_um) is float and one_um == pytest.approx(arrays_um[k], abs=1e-12)
        assert motor.motor_error_um(x, 0.02, (0.08, 0.01), (0.06, -0.02)) == pytest.approx(
            motor_um[k], abs=1e-12)


def test_screw_coordinate_is_eq_15_16_through_the_axis_sign():
    """The screw coordinate written out per side of P_f equals axis_sign · (P_x - P_f) as
    Eq. 15-16 state it, for floats, ints, NumPy floats and arrays, P_f of either sign."""
    rng = np.random.default_rng(19)
    position_mm = np.concatenate((rng.uniform(-900.0, 900.0, 500), [0.0, -141.0, 641.0]))
    for fixed_end_mm in (-141.0, 0.0, 641.0, -3, 7):
        expected_m = mounting.axis_sign(fixed_end_mm) * (position_mm - fixed_end_mm) * 1e-3
        np.testing.assert_array_equal(mounting.screw_coordinate_m(position_mm, fixed_end_mm),
                                      expected_m)
        for k, x in enumerate(position_mm.tolist()):
            for value in (x, np.float64(x)):
                assert mounting.screw_coordinate_m(value, fixed_end_mm) == expected_m[k]
        assert mounting.screw_coordinate_m(12, fixed_end_mm) == mounting.axis_sign(
            fixed_end_mm) * (12.0 - fixed_end_mm) * 1e-3


def test_scalar_clip_equals_numpy_clip():
    """The scalar clip (comparisons) against np.clip at seeded random values, at and beyond
    both bounds, for floats, ints and NumPy floats; NaN stays NaN as in np.clip."""
    rng = np.random.default_rng(23)
    points = np.concatenate((rng.uniform(-3.0, 3.0, 2000), [-1.0, 1.0, -0.0, np.inf, -np.inf]))
    expected = np.clip(points, -1.0, 1.0)
    for k, x in enumerate(points.tolist()):
        for value in (x, np.float64(x)):
            clipped = scalar.clip(value, -1.0, 1.0)
            assert type(clipped) is float and clipped == expected[k]
    assert [scalar.clip(n, -1.0, 1.0) for n in (-2, 0, 3)] == [-1.0, 0.0, 1.0]
    assert np.isnan(scalar.clip(float("nan"), -1.0, 1.0))
    np.testing.assert_array_equal(scalar.clip(points.tolist(), -1.0, 1.0), expected)


def test_scalar_values_give_a_float_or_a_float_array():
    """A float as it is, an int or NumPy float as a float, anything else as a float array;
    values_and_module adds the module its formula runs on."""
    assert [type(scalar.values(v)) for v in (2.5, 2, np.float64(2.5), True)] == [float] * 4
    assert scalar.values(2) == 2.0 and scalar.values(np.float64(2.5)) == 2.5
    assert scalar.values([1, 2]).dtype == float and scalar.values(np.arange(2)).dtype == float
    assert scalar.values_and_module(3) == (3.0, math)
    one, xp = scalar.values_and_module([3])
    assert xp is np and one.dtype == float and one.tolist() == [3.0]


@pytest.mark.parametrize("bad, name", [({"duration_s": -1e-3}, "duration_s"),
                                       ({"duration_s": np.inf}, "duration_s"),
                                       ({"reference_mm": np.nan}, "reference_mm"),
                                       ({"disturbance_N": -np.inf}, "disturbance_N"),
                                       ({"reference_mm": 1e308, "disturbance_N": np.nan},
                                        "disturbance_N")])
def test_servo_advance_refuses_a_bad_input_naming_it(bad, name):
    """One test passes valid inputs; a failing one reaches the checks, which name the input
    and leave the loop as it was. Finite inputs whose sum overflows are valid."""
    loop = servo.Servo(servo.ServoParams(), 1.0)
    before = loop.state()
    with pytest.raises(ParameterError, match=name):
        loop.advance(**{"duration_s": 1e-3, "reference_mm": 1.0, "disturbance_N": 0.0, **bad})
    assert loop.state() == before
    loop.advance(0.0, 1e308, 1e308)
    assert loop.state() == before  # a zero step leaves the loop as it is


def dense_advance(params, rise_K, duration_s, nut_position_mm, feed_mm_min):
    """The thermal update as it was written before the tridiagonal form: the dense rate
    matrix, the sources as k3·s_B + k4·s_N, dt from 1/max|A_nn|, θ + dt (A θ + s)."""
    nut = thermal.nut_cells(params.cells, mounting.screw_coordinate_m(nut_position_mm,
                                                                      params.fixed_end_mm))
    rates = thermal.rate_matrix(params, feed_mm_min, nut)
    sources = np.tensordot([params.k3_W_per_mm_min, params.k4_W_per_mm_min],
                           thermal.unit_source_rates(params, feed_mm_min, nut), axes=1)
    stable_s = min(params.time_step_s, 1.0 / np.max(np.abs(np.diag(rates))))
    n_sub = max(1, int(np.ceil(duration_s / stable_s - 1e-9)))
    for _ in range(n_sub):
        rise_K = rise_K + duration_s / n_sub * (rates @ rise_K + sources)
    return rise_K


@pytest.mark.parametrize("conductivity_W_mK", (566.3, 4000.0))
def test_thermal_update_equals_the_dense_matrix_scheme(conductivity_W_mK):
    """advance (tridiagonal, cached cell terms) against the dense scheme over seeded random
    steps, nut positions (also off the screw) and feeds; λ = 4000 forces sub-steps. The same
    explicit Euler recursion in another summation order: equal within 1e-9 K."""
    params = thermal.ThermalScrewParams(conductivity_W_mK=conductivity_W_mK)
    rng = np.random.default_rng(13)
    ours = dense = np.zeros(params.n_cells)
    for _ in range(1500):
        step = (float(rng.choice([0.1, 0.05, 0.37, 1.0, 2.9])), float(rng.uniform(-300, 900)),
                float(rng.uniform(-9000, 9000)))
        ours = thermal.advance(params, ours, *step)
        dense = dense_advance(params, dense, *step)
    assert ours.max() > 1.0
    np.testing.assert_allclose(ours, dense, rtol=0, atol=1e-9)


def test_thermal_outputs_of_one_point_equal_the_array_path():
    """The FMU's outputs at one float position (no arrays) against np.interp on the
    cumulative field (the array path), in and beyond the screw, both sides of P_f."""
    rng = np.random.default_rng(17)
    for fixed_end_mm in (-141.0, 641.0):
        params = thermal.ThermalScrewParams(fixed_end_mm=fixed_end_mm)
        rise_K = rng.uniform(0.0, 30.0, params.n_cells)
        position_mm = np.concatenate((rng.uniform(-400.0, 1100.0, 500), [fixed_end_mm]))
        screw_m = mounting.screw_coordinate_m(position_mm, fixed_end_mm)
        arrays_um = thermal.thermal_error_um(params, rise_K[None, :].repeat(501, axis=0),
                                             position_mm, 1.5)
        along_um = thermal.screw_elongation_um(params, rise_K, np.asarray(screw_m))
        for k, x in enumerate(position_mm.tolist()):
            assert thermal.thermal_error_um(params, rise_K, x, 1.5) == pytest.approx(
                arrays_um[k], rel=1e-12, abs=1e-12)
            assert thermal.screw_elongation_um(params, rise_K, float(screw_m[k])) == \
                pytest.approx(along_um[k], rel=1e-12, abs=1e-12)


def test_play_crosses_the_backlash_over_b_of_travel_back():
    """The nut crosses its play of B over B of reversed travel (the error from +B/2 to
    -B/2); creep inside it changes nothing (the ISO samples of a settling servo); B = 0
    follows every reversal. Scalar and array errors agree, ±1 gives ±B/2."""
    engagement = geometry.play_engagement(1.0, -0.0025, 10.0)  # 2.5 µm back of a 10 µm play
    assert engagement == pytest.approx(0.5)
    assert geometry.backlash_error_um(engagement, 10.0) == pytest.approx(2.5)
    engagement = geometry.play_engagement(engagement, -0.0100, 10.0)
    assert engagement == -1.0 and geometry.backlash_error_um(engagement, 10.0) == -5.0
    assert geometry.play_engagement(1.0, -1e-12, 10.0) == pytest.approx(1.0, abs=1e-9)
    assert geometry.play_engagement(1.0, -1e-12, 0.0) == -1.0
    assert geometry.play_engagement(-1.0, 0.0, 0.0) == -1.0
    directions = np.array([1.0, -1.0, 0.5, 0.0])
    np.testing.assert_array_equal(geometry.backlash_error_um(directions, 4.0), [2, -2, 1, 0])
    assert [geometry.backlash_error_um(float(d), 4.0) for d in directions] == [2, -2, 1, 0]
