"""The loop's forward sensitivities (feedaxis.physics.servo_sensitivity) against central
differences of the loop itself, and the fit and diagnosis they speed up against the slow
paths, on seeded records."""
from dataclasses import replace

import numpy as np
import pytest

from feedaxis.case import read_case
from feedaxis.diagnose import Refitter, diagnose
from feedaxis.effects import CATALOG, Model
from feedaxis.fit import fit
from feedaxis.measurement import Measurement
from feedaxis.physics.servo import ServoParams, simulate, step_counts
from feedaxis.physics.servo_sensitivity import coefficient_jacobian, simulate_sensitivity
from tracking_synthetic import step_loop, two_sines, write_tracking_case

TIME_S = np.arange(0.0, 2.0, 1e-3)
REFERENCE_MM = 2.0 * np.sin(np.pi * TIME_S) + 0.3 * np.sin(14.0 * np.pi * TIME_S)
PID = ServoParams(plant_gain_mm_per_Vs2=70000.0, plant_damping_per_s=150.0,
                  plant_stiffness_per_s2=250.0, delay_s=0.00123)
CASCADE = ServoParams(controller="cascade", kp_per_s=40.0, kv_V_s_per_mm=0.2,
                      plant_gain_mm_per_Vs2=4000.0, plant_damping_per_s=5.0,
                      plant_stiffness_per_s2=10.0, delay_s=0.00055,
                      force_constant_N_per_V=20.0, time_step_s=0.00025)
LOOPS = {
    "PID, Coulomb and viscous friction, constant force":
        replace(PID, friction_N=1.5, damping_N_s_per_mm=0.01, force_N=2.0),
    "NPID, Stribeck friction": replace(PID, controller="npid", coulomb_N=1.0, static_N=2.0,
                                       stribeck_velocity_mm_s=3.0),
    "P-P cascade, Coulomb friction": replace(CASCADE, friction_N=5.0),
    "P-P cascade with feed-forward, constant force":
        replace(CASCADE, velocity_feedforward=1.0, friction_N=2.0, force_N=-3.0),
    "P-PI cascade with feed-forward, Stribeck friction, constant force":
        replace(CASCADE, tn_s=0.02, velocity_feedforward=1.0, coulomb_N=4.0, static_N=6.0,
                stribeck_velocity_mm_s=2.0, force_N=-3.0),
}
FITTED = ("plant_gain_mm_per_Vs2", "plant_damping_per_s", "plant_stiffness_per_s2", "delay_s",
          "friction_N", "damping_N_s_per_mm", "coulomb_N", "static_N",
          "stribeck_velocity_mm_s", "force_N")
# Central differences at relative steps of 1e-4 and 1e-6: the larger step loses accuracy where
# it straddles the friction's kinks (the sign's ramp clipped at ±1: up to 7e-3 of a column
# on these loops), the smaller to rounding (the discretised plant's coefficients carry
# ~1e-16 relative noise the difference divides by the step: up to 4e-4 on the cascade's
# stiffness); the better of the two is within 1.2e-6 of the largest value of the column on
# every loop here, and the sensitivities must agree with it within 1e-5.
STEPS = (1e-4, 1e-6)
TOLERANCE = 1e-5


@pytest.mark.parametrize("label", sorted(LOOPS))
def test_the_sensitivities_are_the_central_differences_of_the_loop(label):
    params = LOOPS[label]
    stribeck = params.static_N > 0.0
    names = [name for name in FITTED if getattr(params, name) != 0.0
             and (stribeck or name != "stribeck_velocity_mm_s")]
    counts = step_counts(TIME_S, params.time_step_s)
    position_mm, jacobian = simulate_sensitivity(params, names, TIME_S, REFERENCE_MM, None,
                                                 counts)
    # the positions are the loop's own, to the bit
    np.testing.assert_array_equal(position_mm, simulate(params, TIME_S, REFERENCE_MM, None,
                                                        counts))
    for column, name in enumerate(names):
        errors = []
        for relative in STEPS:
            differences = _central_difference(params, name, relative, counts)
            scale = np.max(np.abs(differences))
            assert scale > 0.0, name
            errors.append(np.max(np.abs(jacobian[:, column] - differences)) / scale)
        assert min(errors) <= TOLERANCE, (name, errors)


def _central_difference(params, name, relative, counts):
    """d position / d ``name`` by central differences at ``relative`` times its value."""
    value = getattr(params, name)
    step = relative * abs(value)
    return (simulate(replace(params, **{name: value + step}), TIME_S, REFERENCE_MM, None, counts)
            - simulate(replace(params, **{name: value - step}), TIME_S, REFERENCE_MM, None,
                       counts)) / (2.0 * step)


@pytest.mark.parametrize("label", ("PID", "P-PI cascade with feed-forward"))
def test_the_friction_columns_at_zero_friction_are_the_one_sided_differences(label):
    """Where every friction force is 0 (a fit's start) the loop is still linear in each of
    them to first order: their columns are not 0. The forces cannot go below 0, so the
    differences are one-sided, Richardson-extrapolated from steps of 1e-4 and 5e-5 N
    (measured: within 6.1e-7 of the column's largest value, the plain difference at 5e-5 N
    within 1.7e-4; before the fix the columns were 0)."""
    params = {"PID": PID, "P-PI cascade with feed-forward":
              replace(CASCADE, tn_s=0.02, velocity_feedforward=1.0)}[label]
    names = ("friction_N", "coulomb_N", "static_N")
    counts = step_counts(TIME_S, params.time_step_s)
    position_mm, jacobian = simulate_sensitivity(params, names, TIME_S, REFERENCE_MM, None,
                                                 counts)
    for column, name in enumerate(names):
        coarse, fine = ((simulate(replace(params, **{name: step}), TIME_S, REFERENCE_MM, None,
                                  counts) - position_mm) / step for step in (1e-4, 5e-5))
        differences = 2.0 * fine - coarse
        scale = np.max(np.abs(differences))
        assert scale > 0.0, name
        assert np.max(np.abs(jacobian[:, column] - differences)) <= TOLERANCE * scale, name


def test_the_coefficient_jacobian_refuses_what_it_does_not_differentiate():
    with pytest.raises(ValueError, match="time_step_s"):
        coefficient_jacobian(PID, ["time_step_s"])


PLANT = {"plant_gain_mm_per_Vs2": 70000.0, "plant_damping_per_s": 150.0,
         "plant_stiffness_per_s2": 250.0, "delay_s": 0.0015}


@pytest.fixture(scope="module")
def friction_case(tmp_path_factory):
    run = step_loop(two_sines, 2.0, plant=PLANT, friction_N=1.5)
    return read_case(write_tracking_case(tmp_path_factory.mktemp("c") / "case", run, 5))


def test_the_fit_from_sensitivities_reaches_the_differences_optimum(friction_case, monkeypatch):
    """Both paths stop at the optimiser's tolerances (relative changes of 1e-8 in cost and
    step), each along its own path: the exact Jacobian steers otherwise than one carrying
    the differences' error (about 1e-8 relative), so the fits agree to where they stop,
    not to the last bit. Measured on this case: the sensitivities' sum of squares is lower
    by 1.6e-9 of it, the values differ by at most 4e-4 of their standard uncertainties
    (2.4e-5 relative, the delay)."""
    model = Model((CATALOG["servo_plant"], CATALOG["coulomb_friction"]))
    exact = fit(model, friction_case)
    monkeypatch.setattr(Measurement, "sensitivities", False)
    differenced = fit(model, friction_case)
    exact_ss, differenced_ss = (float(r.residual_um @ r.residual_um)
                                for r in (exact, differenced))
    assert exact_ss <= differenced_ss * (1.0 + 1e-12)
    assert exact_ss == pytest.approx(differenced_ss, rel=1e-7)
    for effect in model.names:
        for name, value in exact.model.values[effect].items():
            sigma = exact.uncertainties[effect][name]
            assert abs(value - differenced.model.values[effect][name]) <= 1e-3 * sigma, name


def test_the_fit_takes_its_jacobian_column_by_column_with_the_same_results(friction_case,
                                                                         monkeypatch):
    """The sensitivities and the fit's Jacobian are stored column by column (Fortran order),
    as SciPy's trust region scales and sums them; given row by row (C order, as before) the
    fit reaches the same values within 1e-12 relative and the same uncertainties within
    5e-12 (the trust region's column sums and gradient add in another order: rounding, as
    in :func:`test_the_fused_multiply_adds_move_no_position_and_the_columns_by_rounding`)."""
    from feedaxis.fit import Problem

    model = Model((CATALOG["servo_plant"], CATALOG["coulomb_friction"]))
    by_column = fit(model, friction_case)
    assert by_column.jacobian.flags.f_contiguous
    derivatives, jacobian = Problem.core_derivatives, Problem.jacobian
    monkeypatch.setattr(Problem, "core_derivatives", lambda self, layout, x: np.ascontiguousarray(
        derivatives(self, layout, x)))
    monkeypatch.setattr(Problem, "jacobian", lambda self, layout: (
        lambda x, at=jacobian(self, layout): np.ascontiguousarray(at(x))))
    by_row = fit(model, friction_case)
    assert by_row.jacobian.flags.c_contiguous
    for effect in model.names:
        for name, value in by_column.model.values[effect].items():
            assert by_row.model.values[effect][name] == pytest.approx(value, rel=1e-12), name
            assert by_row.uncertainties[effect][name] == pytest.approx(
                by_column.uncertainties[effect][name], rel=5e-12), name


def test_the_diagnosis_keeps_each_fit_once_and_finds_the_same(friction_case, monkeypatch):
    """The refitter's memo returns the fit the selection made (same effects, same start):
    the diagnosis's findings are those of refitting every time, to the bit."""
    model = Model((CATALOG["servo_plant"],))
    kept = diagnose(friction_case, model).to_json()
    monkeypatch.setattr(Refitter, "fit", lambda self, m: fit(m, self.measurement))
    refitted = diagnose(friction_case, model).to_json()
    assert kept == refitted


def test_the_loops_kept_results_are_those_of_simulating_anew(friction_case, monkeypatch):
    """The measurement keeps the loop's last results by parameters (a fit asks again where
    it stands): a diagnosis with them kept finds what one simulating every time finds, to
    the bit, in fewer simulations; what is kept cannot be written to."""
    from feedaxis.measurement import tracking

    model = Model((CATALOG["servo_plant"],))
    calls = {"loop": 0}
    simulate_once = tracking.simulate

    def counted(*args, **kwargs):
        calls["loop"] += 1
        return simulate_once(*args, **kwargs)

    monkeypatch.setattr(tracking, "simulate", counted)
    kept = diagnose(friction_case, model)
    kept_calls, calls["loop"] = calls["loop"], 0
    monkeypatch.setattr(tracking, "RECENT_BYTES", 0)
    anew = diagnose(friction_case, model)
    assert kept.to_json() == anew.to_json()
    np.testing.assert_array_equal(kept.final.residual_um, anew.final.residual_um)
    assert kept_calls < calls["loop"]
    monkeypatch.undo()
    measurement = tracking.Tracking(friction_case)
    params = measurement.params(model, {"servo_plant": PLANT})
    positions = measurement.positions_mm(params)
    assert measurement.positions_mm(params) is positions and not positions.flags.writeable
    deviation, _ = measurement.deviation_sensitivity(params, ["delay_s"])
    np.testing.assert_array_equal(deviation, measurement.deviation_um(params))


@pytest.mark.parametrize("friction_N", (0.0, 1.5))
def test_the_friction_screen_changes_no_finding(tmp_path, friction_N, monkeypatch):
    """The friction laws screened by their score test before their fit (where the screen
    passes they are fitted as before): the diagnosis finds what fitting them every time
    finds, to the bit, on a null and with friction; on the null neither law is fitted."""
    from feedaxis import diagnose as diagnosis
    from feedaxis.effects.tracking import CoulombFriction, StribeckFriction

    run = step_loop(two_sines, 2.0, plant=PLANT, friction_N=friction_N)
    case = read_case(write_tracking_case(tmp_path / "case", run, 11))
    model = Model((CATALOG["servo_plant"],))
    fitted = []
    fit_once = diagnosis._fit
    monkeypatch.setattr(diagnosis, "_fit",
                        lambda m, data: fitted.append(m.names[-1]) or fit_once(m, data))
    screened = diagnose(case, model)
    laws_fitted, fitted[:] = list(fitted), []
    for law in (CoulombFriction, StribeckFriction):
        monkeypatch.setattr(law, "score_screened", False)
    always = diagnose(case, model)
    assert screened.to_json() == always.to_json()
    np.testing.assert_array_equal(screened.final.residual_um, always.final.residual_um)
    assert {"coulomb_friction", "stribeck_friction"} <= set(fitted)
    if friction_N == 0.0:
        assert screened.verdict == "adequate" and not set(laws_fitted) & {
            "coulomb_friction", "stribeck_friction"}
    else:
        assert [c.effect for c in screened.candidates] == ["coulomb_friction"]


def test_a_loop_parameter_without_sensitivity_is_differenced(friction_case):
    """An effect on a loop parameter the sensitivities do not cover (here the force
    constant) leaves the measurement without them: the fit differences, as before."""
    from feedaxis.effects.tracking import TrackingEffect
    from feedaxis.effects.base import Parameter
    from feedaxis.measurement import Tracking

    class ForceConstant(TrackingEffect):
        name = "force_constant"
        parameters = (Parameter("force_constant_N_per_V", "N/V", 1.0, 1e3, "K_F"),)
        neutral = {"force_constant_N_per_V": 100.0}

    measurement = Tracking(friction_case)
    assert measurement.sensitivity(Model((CATALOG["servo_plant"],))) is not None
    assert measurement.sensitivity(Model((CATALOG["servo_plant"], ForceConstant()))) is None


@pytest.mark.parametrize("label", ("PID", "P-PI cascade with feed-forward"))
def test_the_frictionless_pass_equals_the_full_friction_tangent(label):
    """Without friction and without a friction parameter the pass leaves the friction's
    tangent out (its terms multiply zeros): the plant's columns are those of the pass that
    evaluates it (a friction parameter among the names, at zero force), to the bit; for the
    PID the pass without friction runs its own kernel, whose fused multiply-adds fall
    otherwise (:func:`test_the_plain_pid_pass_is_the_general_one`): within 1e-12 of each
    column's largest value there, the positions to the bit."""
    params = {"PID": PID, "P-PI cascade with feed-forward":
              replace(CASCADE, tn_s=0.02, velocity_feedforward=1.0,
                      damping_N_s_per_mm=0.02)}[label]
    plant = ("plant_gain_mm_per_Vs2", "plant_damping_per_s", "plant_stiffness_per_s2",
             "delay_s")
    counts = step_counts(TIME_S, params.time_step_s)
    short = simulate_sensitivity(params, plant, TIME_S, REFERENCE_MM, None, counts)
    full = simulate_sensitivity(params, (*plant, "friction_N"), TIME_S, REFERENCE_MM, None,
                                counts)
    np.testing.assert_array_equal(short[0], full[0])
    if label == "PID":
        columns = full[1][:, :len(plant)]
        assert _fused_close(short[1], columns, np.abs(columns).max(axis=0))
    else:
        np.testing.assert_array_equal(short[1], full[1][:, :len(plant)])


def _fused_close(derivatives, reference, scale):
    """Whether ``derivatives`` are within 1e-12 of ``scale`` (a column's largest value) of
    ``reference``: two kernels whose multiply-adds are fused in different places (on a
    processor with fused multiply-adds; the loop's own values are not fused)."""
    return np.all(np.abs(derivatives - reference) <= 1e-12 * scale)


@pytest.mark.parametrize("label", ("PID", "P-PI cascade with feed-forward"))
def test_the_loop_without_friction_skips_it_and_gives_the_friction_paths_numbers(label):
    """Where no friction force acts the loop and the pass take the known force as it is
    (servo.resists); a viscous friction of 1e-300 N.s/mm takes the friction's path and moves
    nothing a double can hold: the positions and the plant's columns agree within 1e-12
    relative (to the bit but for values under 1e-250)."""
    params = {"PID": PID, "P-PI cascade with feed-forward":
              replace(CASCADE, tn_s=0.02, velocity_feedforward=1.0)}[label]
    resisted = replace(params, damping_N_s_per_mm=1e-300)
    plant = ("plant_gain_mm_per_Vs2", "plant_damping_per_s", "plant_stiffness_per_s2",
             "delay_s")
    counts = step_counts(TIME_S, params.time_step_s)
    for fast, slow in zip(
            (simulate(params, TIME_S, REFERENCE_MM, None, counts),
             *simulate_sensitivity(params, plant, TIME_S, REFERENCE_MM, None, counts)),
            (simulate(resisted, TIME_S, REFERENCE_MM, None, counts),
             *simulate_sensitivity(resisted, plant, TIME_S, REFERENCE_MM, None, counts))):
        np.testing.assert_allclose(fast, slow, rtol=1e-12, atol=1e-250)
        assert np.abs(fast).max() > 1e-3


@pytest.mark.parametrize("label", ("PID", "P-PI cascade with feed-forward"))
def test_the_coulomb_column_without_the_rise_at_rest_is_the_one_beside_it_to_the_bit(label):
    """The pass leaves the Stribeck decay (an exponential per step) out where no rise at rest
    acts and none of its parameters moves; with them among the names it is evaluated, and
    the Coulomb force's column and the positions are the same to the bit."""
    params = {"PID": PID, "P-PI cascade with feed-forward":
              replace(CASCADE, tn_s=0.02, velocity_feedforward=1.0, friction_N=2.0)}[label]
    counts = step_counts(TIME_S, params.time_step_s)
    alone = simulate_sensitivity(params, ("friction_N",), TIME_S, REFERENCE_MM, None, counts)
    beside = simulate_sensitivity(params, ("friction_N", "coulomb_N", "static_N",
                                           "stribeck_velocity_mm_s"), TIME_S, REFERENCE_MM,
                                  None, counts)
    np.testing.assert_array_equal(alone[0], beside[0])
    np.testing.assert_array_equal(alone[1][:, 0], beside[1][:, 0])
    assert np.abs(beside[1][:, 1:3]).max() > 0.0


def test_the_stribeck_decay_skips_only_what_underflows_to_zero():
    """The decay exp(−(v/v_s)²) is taken as 0 beyond (v/v_s)² = DECAY_UNDERFLOW without the
    exponential: there the exponential is 0 itself, so the friction and its tangent are the
    same to the bit on both sides of the threshold."""
    import math

    from feedaxis.physics.servo import DECAY_UNDERFLOW, stribeck_V
    from feedaxis.physics.servo_sensitivity import friction_tangent

    assert math.exp(-DECAY_UNDERFLOW) == 0.0
    for ratio in np.concatenate([np.linspace(-40.0, 40.0, 8001), [-math.inf, math.inf]]):
        plain = 1.0 + (3.0 - 1.0) * math.exp(-ratio * ratio)
        assert stribeck_V(2.0 * ratio, 1.0, 3.0, 2.0) == plain
        tangent = friction_tangent(2.0 * ratio, 0.5, 0.01, 1.0, 3.0, 2.0, 0.1, True)
        assert tangent[4] == math.exp(-ratio * ratio) * tangent[1]
    assert math.isnan(stribeck_V(math.nan, 1.0, 3.0, 2.0))


@pytest.mark.parametrize("delay_s", (0.00123, 0.0015, 0.0))
def test_the_plain_pid_pass_is_the_general_one(delay_s):
    """The plant's pass of a PID loop without friction runs its own kernel (no branch in its
    inner loops): positions and final state those of the general pass to the bit, its
    columns and their final state within 1e-12 of each column's largest value (each
    kernel's derivatives fuse their multiply-adds where its own code allows:
    :func:`~feedaxis.physics.servo_sensitivity.compiled_tangent`), with a known and a
    constant force; a friction, a gain or another controller takes the general pass."""
    from feedaxis.physics.servo import forces_V, loop_coefficients
    from feedaxis.physics.servo_sensitivity import (PLANT as PLANT_NAMES,
                                                    compiled_pid_tangent, compiled_tangent,
                                                    plain_pid)

    params = replace(PID, delay_s=delay_s, force_N=0.7)
    names = (*PLANT_NAMES, "force_N")
    counts = step_counts(TIME_S, params.time_step_s)
    force_N = 0.3 * np.sin(40.0 * TIME_S)
    coefficients = loop_coefficients(params)
    assert plain_pid(coefficients, names)
    d_coefficients, d_force = coefficient_jacobian(params, names)
    runs = []
    for kernel in (compiled_pid_tangent(), compiled_tangent()):
        state = np.array([REFERENCE_MM[0], 0.0, 0.0, 0.0, REFERENCE_MM[0], 0.0])
        d_state = np.zeros((4, len(names)))
        positions, columns = np.empty(TIME_S.size), np.zeros((len(names), TIME_S.size))
        kernel(coefficients, np.ascontiguousarray(d_coefficients.T), counts, REFERENCE_MM,
               forces_V(params, force_N, TIME_S.size), d_force, state,
               np.zeros(params.buffer_size), d_state, np.zeros((params.buffer_size, len(names))),
               positions, columns)
        runs.append((positions, columns, state, d_state))
    for kept, (plain, general) in enumerate(zip(*runs)):
        if kept % 2 == 0:  # the positions and the loop's state
            np.testing.assert_array_equal(plain, general)
        else:  # the derivatives, a parameter's along a column of d_state, a row of columns
            scale = np.abs(general).max(axis=1 if kept == 1 else 0)
            assert _fused_close(plain, general, scale[:, None] if kept == 1 else scale)
    assert np.abs(runs[0][1]).max(axis=1).min() > 0.0  # every parameter's row moves
    for other, other_names in ((replace(params, friction_N=1.0), names),
                               (replace(params, damping_N_s_per_mm=0.01), names),
                               (replace(params, controller="npid"), names),
                               (CASCADE, PLANT_NAMES), (params, (*names, "kp_V_per_mm"))):
        assert not plain_pid(loop_coefficients(other), other_names)


def test_the_fused_multiply_adds_move_no_position_and_the_columns_by_rounding(friction_case,
                                                                                monkeypatch):
    """The tangent kernels' derivatives are compiled with fused multiply-adds, the loop's
    own values without: against the same kernels compiled without them (not cached), the
    positions are the same to the bit and the columns within 1e-12 of each column's
    largest value (measured on 500 s at 1 ms: within 4e-15), on the plant's PID pass and
    a general one (NPID, Stribeck friction, a gain); the fits of the plant and of the plant
    with a Coulomb friction on a seeded record reach the same values within 1e-12 relative
    and the same uncertainties within 5e-12 (measured 1.5e-12: the Jacobian perturbed at
    random by one unit in its last place moves them by up to 1.6e-12 on this record, the
    values by up to 6e-13)."""
    import numba

    from feedaxis.physics import servo_sensitivity

    plain = {kernel.__name__: numba.njit(servo_sensitivity.numba_ready_tangent(kernel))
             for kernel in (servo_sensitivity.run_loop_tangent_pid,
                            servo_sensitivity.run_loop_tangent)}
    general = replace(PID, controller="npid", coulomb_N=1.0, static_N=2.0,
                      stribeck_velocity_mm_s=3.0)
    for params, names in ((PID, servo_sensitivity.PLANT),
                          (general, (*servo_sensitivity.PLANT, "static_N", "ko_per_mm"))):
        counts = step_counts(TIME_S, params.time_step_s)
        fused = simulate_sensitivity(params, names, TIME_S, REFERENCE_MM, None, counts)
        kernel = "run_loop_tangent_pid" if params is PID else "run_loop_tangent"
        monkeypatch.setattr(servo_sensitivity, "compiled_pid_tangent" if params is PID else
                            "compiled_tangent", lambda kernel=kernel: plain[kernel])
        reference = simulate_sensitivity(params, names, TIME_S, REFERENCE_MM, None, counts)
        monkeypatch.undo()
        np.testing.assert_array_equal(fused[0], reference[0])
        assert _fused_close(fused[1], reference[1], np.abs(reference[1]).max(axis=0))
    plant = Model((CATALOG["servo_plant"],))
    for model in (plant, Model((CATALOG["servo_plant"], CATALOG["coulomb_friction"]))):
        fused = fit(model, friction_case)
        monkeypatch.setattr(servo_sensitivity, "compiled_pid_tangent",
                            lambda: plain["run_loop_tangent_pid"])
        monkeypatch.setattr(servo_sensitivity, "compiled_tangent",
                            lambda: plain["run_loop_tangent"])
        reference = fit(model, friction_case)
        monkeypatch.undo()
        for effect in model.names:
            for name, value in reference.model.values[effect].items():
                assert fused.model.values[effect][name] == pytest.approx(value, rel=1e-12)
                assert fused.uncertainties[effect][name] == pytest.approx(
                    reference.uncertainties[effect][name], rel=5e-12), name
