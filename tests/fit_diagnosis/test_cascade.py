"""Servo traces from real drives (issue 31): the cascade loop industrial drives run, a start
identified from the record, and findings in the shape a servo engineer names them.

Records come from tests/cascade_synthetic.py: the cascade stepped by classical Runge-Kutta
independently of feedaxis.physics.servo, with seeded encoder noise (white 0.1 µm + AR(1)
0.3 µm). Sizes are asserted within 3 standard uncertainties of the generating values.
"""
import json
import math

import numpy as np
import pytest

from cascade_synthetic import (CASCADES, FORCE_CONSTANT_N_PER_V, LOOP_STEP_S, PLANT,
                               cascade_loop, exciting, servo_table, write_cascade_case)
from feedaxis.case import CaseError, read_case, write_case
from feedaxis.cli import main
from feedaxis.diagnose import diagnose
from feedaxis.effects import CATALOG, Model
from feedaxis.physics import servo
from feedaxis.physics.identify import identify_plant

DURATION_S = 3.0


def _params(cascade, **extra):
    table = servo_table(cascade)
    gains = {key: table[key] for key in CASCADES[cascade]}
    return servo.ServoParams(controller="cascade", force_constant_N_per_V=FORCE_CONSTANT_N_PER_V,
                             time_step_s=LOOP_STEP_S, **gains, **PLANT, **extra)


def _train(t):
    """A 1 Hz train of force steps: 2 N during the second half of every second."""
    return 2.0 if t % 1.0 >= 0.5 else 0.0


@pytest.mark.parametrize("cascade", sorted(CASCADES))
def test_the_cascade_kernel_equals_an_independent_stepping_of_the_loop(cascade):
    """physics.servo's cascade (the fit's compiled kernel) against the Runge-Kutta generator,
    with Coulomb and Stribeck friction, a constant force and a force train: position and
    recorded controller output agree to 1e-9."""
    friction = {"friction_N": 1.0, "coulomb_N": 3.0, "static_N": 6.0,
                "stribeck_velocity_mm_s": 2.0}
    time_s, reference_mm, position_mm, control_V = cascade_loop(
        exciting, 1.0, cascade, force_N=lambda t: -3.0 + _train(t), **friction)
    force_N = np.array([-3.0 + _train(t) for t in time_s])
    simulated_mm, simulated_V = servo.simulate_record(_params(cascade, **friction), time_s,
                                                      reference_mm, force_N)
    assert np.max(np.abs(simulated_mm - position_mm)) < 1e-9
    assert np.max(np.abs(simulated_V - control_V)) < 1e-9


def test_the_fmu_loop_steps_the_cascade_as_the_fit_simulates_it():
    """Servo (the NpidServo FMU's physics, stepped in Python at 1 ms) against simulate, and
    its control_V output against the recorded one."""
    params = _params("P-PI ff", friction_N=2.0, force_N=-1.5)
    time_s = np.arange(0.0, 0.5, 1e-3)
    reference_mm = np.array([exciting(t) for t in time_s])
    positions, controls = servo.simulate_record(params, time_s, reference_mm)
    loop = servo.Servo(params, reference_mm[0], loop=None)
    for i in range(1, time_s.size):
        loop.advance(1e-3, reference_mm[i])
        position, _, error, control = loop.outputs()
        assert position == pytest.approx(positions[i], abs=1e-12)
        assert control == pytest.approx(controls[i], abs=1e-12)


def test_the_case_reader_takes_a_cascade_and_refuses_mixed_keys(tmp_path):
    time_s = np.arange(0.0, 1.0, 1e-3)
    columns = {"time_s": time_s, "reference_mm": np.sin(time_s), "actual_mm": np.sin(time_s),
               "control_V": np.zeros_like(time_s)}
    axis = {"name": "drive", "screw": {"lead_mm": 10.0}, "servo": servo_table("P-PI ff")}
    case = read_case(write_case(tmp_path / "ok", axis, tracking=columns))
    assert case.axis.servo["controller"] == "cascade" and case.tracking.control_V is not None
    for name, servo_values, column in (
            ("pid-key", {**servo_table("P-P"), "kp_V_per_mm": 1.0}, "servo.kp_V_per_mm"),
            ("feedforward", {**servo_table("P-P"), "velocity_feedforward": 1.5},
             "servo.velocity_feedforward"),
            ("no-kv", {k: v for k, v in servo_table("P-P").items() if k != "kv_V_s_per_mm"},
             "servo.kv_V_s_per_mm")):
        folder = write_case(tmp_path / name, {**axis, "servo": servo_values}, tracking=columns)
        with pytest.raises(CaseError) as error:
            read_case(folder)
        assert error.value.column == column
    pid = {"controller": "pid", "kp_V_per_mm": 1.0, "ki_V_per_mm_s": 0.0, "kd_V_s_per_mm": 0.0,
           "force_constant_N_per_V": 100.0, "kp_per_s": 40.0}
    with pytest.raises(CaseError) as error:
        read_case(write_case(tmp_path / "pid", {**axis, "servo": pid}, tracking=columns))
    assert error.value.column == "servo.kp_per_s"
    loud = {**columns, "control_V": np.full_like(time_s, 2e4)}
    with pytest.raises(CaseError) as error:
        read_case(write_case(tmp_path / "loud", axis, tracking=loud))
    assert error.value.column == "control_V"


def test_inverse_dynamics_on_control_v_gives_friction_and_force_as_a_start():
    """Coulomb friction and a constant force from the recorded controller output within 2 %
    and 0.05 N, the plant's gain within a factor 1.5: a start. The output is recorded once
    per 1 ms sample while the loop steps four times and its velocity loop crosses over near
    130 Hz, a model error beyond the noise its standard uncertainties describe; the
    closed-loop fit sizes the plant and the effects (tests below)."""
    time_s, _, position_mm, control_V = cascade_loop(exciting, 5.0, "P-PI ff", friction_N=5.0,
                                                    force_N=lambda t: -3.0)
    noisy_mm = position_mm + np.random.default_rng(1).normal(0.0, 0.03e-3, time_s.size)
    found = identify_plant(time_s, noisy_mm, control_V, FORCE_CONSTANT_N_PER_V)
    assert found.values["friction_N"] == pytest.approx(5.0, rel=0.02)
    assert found.values["force_N"] == pytest.approx(-3.0, abs=0.05)
    assert 4000.0 / 1.5 < found.values["plant_gain_mm_per_Vs2"] < 4000.0 * 1.5


def _diagnosed(tmp_path, cascade, control, seed=3, duration_s=DURATION_S, model=None,
               **hidden):
    record = cascade_loop(exciting, duration_s, cascade, **hidden)
    case = read_case(write_cascade_case(tmp_path / "case", record, cascade, seed, control))
    return case, diagnose(case, model or Model())


def _assert_within(found, effect, truths):
    values = found.final.model.values[effect]
    sigma = found.final.uncertainties[effect]
    for name, truth in truths.items():
        assert abs(values[name] - truth) < 3 * sigma[name], (effect, name, values[name], truth)


@pytest.mark.parametrize("control", (False, True), ids=("no control_V", "control_V"))
@pytest.mark.parametrize("cascade", sorted(CASCADES))
def test_a_null_drive_from_the_empty_model_is_adequate(tmp_path, cascade, control):
    """No hidden effect: from the empty model (the start from the record) `adequate`, and
    the command-line diagnosis exits 0 (never 2)."""
    case, found = _diagnosed(tmp_path, cascade, control)
    assert found.verdict == "adequate", (found.candidates, found.unexplained)
    assert main(["diagnose", str(case.folder), "--json"]) == 0


@pytest.mark.parametrize("cascade", sorted(CASCADES))
def test_hidden_coulomb_friction_is_named_with_its_size(tmp_path, cascade):
    _, found = _diagnosed(tmp_path, cascade, False, friction_N=5.0)
    assert "coulomb_friction" in [c.effect for c in found.candidates]
    assert "stribeck_friction" not in [c.effect for c in found.candidates]
    _assert_within(found, "coulomb_friction", {"friction_N": 5.0})


STRIBECK = {"coulomb_N": 3.0, "static_N": 6.0, "stribeck_velocity_mm_s": 2.0}


@pytest.mark.parametrize("cascade, control", (("P-P", False), ("P-P ff", True), ("P-PI", True),
                                              ("P-PI ff", False), ("P-PI ff", True)))
def test_hidden_stribeck_friction_is_named_with_its_size(tmp_path, cascade, control):
    """A Stribeck rise the catalog's law describes: named with its three sizes within 3
    standard uncertainties, nothing left at the reversals."""
    _, found = _diagnosed(tmp_path, cascade, control, **STRIBECK)
    named = [c.effect for c in found.candidates]
    assert "stribeck_friction" in named and "coulomb_friction" not in named
    _assert_within(found, "stribeck_friction", STRIBECK)
    assert not found.unexplained


@pytest.mark.parametrize("hidden", ({**STRIBECK}, {"friction_N": 3.0, "spike_N": 3.0,
                                                   "spike_decay_s": 0.02}),
                         ids=("Stribeck rise", "breaking away over time"))
@pytest.mark.parametrize("cascade", ("P-P", "P-PI ff"))
def test_reversal_spikes_no_friction_law_carries_are_found_at_the_reversals(tmp_path, cascade,
                                                                            hidden):
    """Friction at rest that no effect tried carries (the catalog without the Stribeck
    law; or a rise that decays in time after each reversal, which no velocity law is):
    Coulomb friction is named and the spikes are described at the velocity reversals, with
    their height within 40 % of the spike the simulation made (the same record simulated
    with Coulomb friction alone, subtracted) and a decay under the 0.2 s looked at, never
    as periodic forces, bursts or force steps."""
    effects = {name: effect for name, effect in CATALOG.items() if name != "stribeck_friction"}
    record = cascade_loop(exciting, DURATION_S, cascade, **hidden)
    plain = cascade_loop(exciting, DURATION_S, cascade, friction_N=3.0)
    case = read_case(write_cascade_case(tmp_path / "case", record, cascade, 3))
    found = diagnose(case, Model(), effects=effects)
    assert "coulomb_friction" in [c.effect for c in found.candidates]
    assert [s.kind for s in found.unexplained] == ["reversal"]
    details = found.unexplained[0].to_json()
    settled = record[0] >= 0.2
    spike_um = np.max(np.abs(record[2] - plain[2])[settled]) * 1e3
    assert details["height_um"] == pytest.approx(spike_um, rel=0.4)
    assert 0.0 < details["decay_s"] < 0.2
    turns = record[0][1:-1][np.diff(np.sign(np.diff(record[1]))) != 0]
    assert np.all(np.min(np.abs(np.subtract.outer(turns, details["reversal_times_s"])),
                         axis=1) <= 2e-3)


@pytest.mark.parametrize("cascade, control", (("P-P", False), ("P-P ff", True),
                                              ("P-PI", True), ("P-PI ff", True)))
def test_a_hidden_constant_force_is_named_with_its_size(tmp_path, cascade, control):
    """A P position loop holds a constant force as a steady error; an integral action holds
    it in the controller output, which the recorded control_V shows."""
    _, found = _diagnosed(tmp_path, cascade, control, force_N=lambda t: -3.0)
    assert [c.effect for c in found.candidates][0] == "constant_force"
    _assert_within(found, "constant_force", {"force_N": -3.0})


def test_a_constant_force_under_an_integral_action_without_control_v_is_undetermined(
        tmp_path, capsys):
    """P-PI without the controller output: the integral holds the force, the tracking error
    shows nothing lasting; nothing is named, and constant_force is passed over as
    undetermined with the reason (the integral action, control_V to record), in the text
    too. A P-P loop holds it as a steady error: not passed over there."""
    case, found = _diagnosed(tmp_path, "P-PI", False, force_N=lambda t: -3.0)
    assert found.verdict == "adequate" and not found.candidates
    reason = found.skipped["constant_force"]
    assert reason.startswith("undetermined") and "integral" in reason and "control_V" in reason
    assert main(["diagnose", str(case.folder)]) == 0
    assert "integral action holds a constant force" in capsys.readouterr().out
    _, found = _diagnosed(tmp_path / "p", "P-P", False)
    assert "constant_force" not in found.skipped


@pytest.mark.parametrize("control", (False, True), ids=("position only", "with control_V"))
def test_a_constant_force_under_a_drifting_measurement_needs_control_v(tmp_path, control):
    """P-P with a constant force, the position measured with a drift of 3 µm over the
    record (an encoder on a growing screw): from the position alone the force and the
    measurement's unknown offset are one steady deviation, so constant_force is passed over
    as undetermined (the drift reported); the recorded controller output holds the force
    and not the offset, and with it the force is named with its size."""
    time_s, reference_mm, position_mm, control_V = cascade_loop(exciting, DURATION_S, "P-P",
                                                                force_N=lambda t: -3.0)
    drifting_mm = position_mm + 3e-3 * time_s / time_s[-1]
    case = read_case(write_cascade_case(tmp_path / "case", (time_s, reference_mm, drifting_mm,
                                                             control_V), "P-P", 3, control))
    found = diagnose(case, Model())
    named = [c.effect for c in found.candidates]
    if control:
        assert "constant_force" in named
        _assert_within(found, "constant_force", {"force_N": -3.0})
    else:
        assert "constant_force" not in named
        assert "drift" in [s.kind for s in found.unexplained]
        assert "drifts" in found.skipped["constant_force"]


def test_a_1_hz_train_of_force_steps_is_reported_as_events_with_their_times(tmp_path):
    """2 N on during the second half of every second, 5 s, diagnosed on top of the plant
    (``fit --add servo_plant`` first, as a commissioning engineer would): the steps found as
    events at their times (within 3 samples under the coloured encoder noise), every 0.5 s,
    not as sinusoids at the train's harmonics."""
    case, found = _diagnosed(tmp_path, "P-PI", False, duration_s=5.0, force_N=_train,
                             model=Model((CATALOG["servo_plant"],)))
    steps = [s for s in found.unexplained if s.kind == "force_steps"]
    assert len(steps) == 1
    details = steps[0].to_json()
    expected = np.arange(0.5, 5.0, 0.5)
    assert np.allclose(details["event_times_s"], expected, atol=3.5e-3)
    assert details["period_s"] == pytest.approx(0.5, abs=2e-3)
    sizes = np.array(details["event_sizes_N"])
    assert np.allclose(np.abs(sizes), 2.0, rtol=0.25) and np.all(sizes[::2] > 0)
    assert not [s for s in found.unexplained if s.kind == "periodic"]
    assert main(["diagnose", str(case.folder), "--json"]) == 0


@pytest.mark.parametrize("harmonic", (1, 2))
@pytest.mark.parametrize("cascade, control", (("P-P", False), ("P-P ff", False), ("P-PI", False)))
def test_a_force_turning_with_the_screw_is_named_against_lead_and_speed(tmp_path, cascade,
                                                                        control, harmonic):
    """A force of 0.5 N periodic in the screw's angle (sin(2πk·x/lead), lead 10 mm) while
    the axis runs at 80 mm/s: a periodic force at k·8 Hz, named as the screw's rotation
    (speed/lead) or its harmonic k, its size within 15 % (30 % under the P-PI loop: a ramp
    at one speed excites its plant too little to size a force through the integral action
    more closely; with control_V recorded a constant force and the plant's damping are one
    column at one speed)."""
    def ramp(t):
        return 80.0 * t

    def screw_force(t):
        return 0.5 * math.sin(2.0 * math.pi * harmonic * ramp(t) / 10.0)

    record = cascade_loop(ramp, DURATION_S, cascade, force_N=screw_force)
    case = read_case(write_cascade_case(tmp_path / "case", record, cascade, 3, control))
    found = diagnose(case, Model())
    periodic = [s.to_json() for s in found.unexplained if s.kind == "periodic"]
    assert len(periodic) == 1 and not found.candidates
    details = periodic[0]
    assert details["source"] == "screw" and details["harmonic"] == harmonic
    assert details["rotation_hz"] == pytest.approx(8.0, rel=1e-3)
    assert details["frequency_hz"] == pytest.approx(8.0 * harmonic, abs=0.05)
    assert details["force_N"] == pytest.approx(0.5, rel=0.3 if "PI" in cascade else 0.15)
    assert "screw's rotation" in details["evidence"]


def _point_to_point(t):
    """Moves of 5 mm at 50 mm/s between rests of 0.4 s."""
    cycle, phase = divmod(t, 0.5)
    return 5.0 * cycle + 50.0 * min(phase, 0.1)


@pytest.mark.parametrize("reference, words", (
    (lambda t: 10.0 * math.sin(2.0 * math.pi * 0.5 * t), "a single sine at 0.5 Hz"),
    (_point_to_point, "a point-to-point trajectory of 5 moves"),
    (exciting, "a record with 9 velocity reversals")), ids=("sine", "point-to-point", "reversals"))
def test_the_texts_name_what_the_reference_is(tmp_path, reference, words):
    """What a loosely fixed parameter's reason and the report say the reference is: a sine,
    a point-to-point trajectory with its moves, a record with its reversals (counted on the
    reference as built, the first move within the start-up left out as every comparison
    leaves it)."""
    from feedaxis.measurement import Tracking

    record = cascade_loop(reference, DURATION_S, "P-P")
    measurement = Tracking(read_case(write_cascade_case(tmp_path / "case", record, "P-P", 3)))
    assert measurement.reference_kind() == words
    assert words in measurement.excitation()


@pytest.mark.parametrize("harmonic_share", (0.0, 0.009, 0.011, 0.3))
def test_the_best_sine_fit_is_the_least_squares_fits_at_each_frequency(harmonic_share):
    """The single-sine check's best fit (normal equations, the phasor turned from one
    frequency to the next) is at the frequency where a least-squares fit at each frequency
    anew leaves the least, and leaves its RMS within 1e-11 relative, on an uneven record
    (samples left out as outliers are)."""
    from feedaxis.measurement.tracking import _best_sine_fit

    time_s = np.delete(np.arange(20000) * 1e-3, [17, 5000, 12345])
    values = (10.0 * np.sin(2.0 * np.pi * 0.55 * time_s + 0.3) + 2.0
              + 10.0 * harmonic_share * np.sin(2.0 * np.pi * 7.0 * time_s))
    values -= values.mean()
    frequencies_hz = np.linspace(0.5, 0.6, 41)
    anew = [np.sqrt(np.mean((values - basis @ np.linalg.lstsq(basis, values, rcond=None)[0])
                            ** 2))
            for basis in (np.column_stack((np.cos(phase), np.sin(phase), np.ones_like(phase)))
                          for phase in (2.0 * np.pi * f * (time_s - time_s[0])
                                        for f in frequencies_hz))]
    left, frequency_hz = _best_sine_fit(time_s, values, frequencies_hz)
    expected, expected_hz = min(zip(anew, frequencies_hz))
    assert frequency_hz == expected_hz
    assert left == pytest.approx(expected, rel=1e-11, abs=1e-12 * np.sqrt(np.mean(values ** 2)))


def test_the_report_shows_the_residual_apart_and_names_the_reference(tmp_path):
    """The tracking page of a fitted cascade drive: the residual (measured − model) in a
    panel of its own under the deviation, what the reference is, no seed numbers."""
    record = cascade_loop(exciting, DURATION_S, "P-P", friction_N=5.0)
    folder = str(write_cascade_case(tmp_path / "case", record, "P-P", 3))
    model = str(tmp_path / "m.toml")
    assert main(["fit", folder, "--add", "servo_plant", "--add", "coulomb_friction",
                 "--out", model]) == 0
    assert main(["report", folder, "--model", model, "--out", str(tmp_path / "r.html")]) == 0
    page = (tmp_path / "r.html").read_text(encoding="utf-8")
    assert "The reference: a record with 9 velocity reversals." in page
    assert "and the residual below it" in page
    assert "seed 0" not in page.lower()


def test_the_built_fmu_runs_a_cascade_drive_as_the_fit_simulates_it(fmu_paths):
    """NpidServo with ``controller = "cascade"`` (its compiled loop) against the physics'
    loop stepped alike in Python (fmpy sets each step's input at the step's start), with
    Coulomb friction and a constant force; tracking_error_mm is position − reference."""
    from fmpy import simulate_fmu

    friction = {"friction_N": 2.0, "force_N": -1.5}
    params = _params("P-PI ff", **friction)
    step_s, n = 1e-3, 400
    time_s = np.arange(n + 1) * step_s
    reference_mm = np.array([exciting(t) for t in time_s])
    signal = np.array(list(zip(time_s, reference_mm)),
                      dtype=[("time", float), ("position_ref_mm", float)])
    start = {"controller": "cascade", "time_step_s": LOOP_STEP_S,
             "force_constant_N_per_V": FORCE_CONSTANT_N_PER_V, **PLANT, **friction,
             **{key: value for key, value in servo_table("P-PI ff").items()
                if key in ("kp_per_s", "kv_V_s_per_mm", "tn_s", "velocity_feedforward")}}
    result = simulate_fmu(str(fmu_paths["NpidServo"]), stop_time=n * step_s, step_size=step_s,
                          output_interval=step_s, input=signal, start_values=start,
                          output=["position_mm", "tracking_error_mm", "control_V"])
    loop = servo.Servo(params, reference_mm[0], loop=servo.run_loop)
    expected = []
    for i in range(n):
        loop.advance(step_s, reference_mm[i])
        expected.append(loop.outputs())
    position, _, error, control = np.array(expected).T
    np.testing.assert_allclose(result["position_mm"][1:], position, rtol=0, atol=1e-9)
    np.testing.assert_allclose(result["control_V"][1:], control, rtol=0, atol=1e-9)
    np.testing.assert_allclose(result["tracking_error_mm"][1:], error, rtol=0, atol=1e-9)
    assert np.allclose(error, position - reference_mm[:n])  # each step's input, its target


def test_a_drive_trace_export_is_imported_through_a_column_map(tmp_path, capsys):
    """A drive's export (semicolon-separated, decimal comma, µm, a sample index): mapped and
    scaled into tracking.csv with control_V; the unmapped column reported; a column the
    export lacks and a target the format lacks are refused, named, exit 2, nothing written."""
    time_s, reference_mm, position_mm, control_V = cascade_loop(exciting, 0.5, "P-PI")
    lines = ["Sample;Pos_cmd [um];Pos_act [um];I_q [A];n_act [rpm]"]
    lines += [f"{i};{r * 1e3:.6f};{a * 1e3:.6f};{u:.9f};0".replace(".", ",")
              for i, (r, a, u) in enumerate(zip(reference_mm, position_mm, control_V))]
    export = tmp_path / "trace.csv"
    export.write_text("\n".join(lines) + "\n", encoding="utf-8")
    axis = tmp_path / "axis.toml"
    axis.write_text('name = "drive"\n[screw]\nlead_mm = 10.0\n[servo]\ncontroller = "cascade"\n'
                    'kp_per_s = 40.0\nkv_V_s_per_mm = 0.2\ntn_s = 0.02\n'
                    'force_constant_N_per_V = 20.0\nloop_step_s = 0.00025\n', encoding="utf-8")
    mapping = ["--map", "sample=Sample", "--sample-time-s", "0.001",
               "--map", "reference_mm=Pos_cmd [um]*0.001", "--map", "actual_mm=Pos_act [um]*0.001",
               "--map", "control_V=I_q [A]"]
    assert main(["import", str(export), "--axis", str(axis), "--out", str(tmp_path / "case"),
                 *mapping, "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["dropped"] == {"n_act [rpm]": "not mapped (--map TARGET=SOURCE to keep it)"}
    trace = read_case(tmp_path / "case").tracking
    np.testing.assert_allclose(trace.time_s, time_s, atol=1e-12)
    np.testing.assert_allclose(trace.actual_mm, position_mm, atol=1e-9)
    np.testing.assert_allclose(trace.control_V, control_V, atol=1e-9)
    for wrong, named in ((["--map", "reference_mm=Pos_cmd*0.001"], "Pos_cmd"),
                         (["--map", "velocity_mm_s=n_act [rpm]"], "velocity_mm_s")):
        assert main(["import", str(export), "--axis", str(axis), "--out",
                     str(tmp_path / "refused"), *mapping, *wrong]) == 2
        assert named in capsys.readouterr().err
        assert not (tmp_path / "refused").exists()


def test_a_record_no_plant_starts_is_undetermined_naming_what_is_missing(tmp_path, capsys,
                                                                         monkeypatch):
    """Where the closed-loop search finds no plant making a stable loop with the cascade of
    [servo] (forced here: the search returns none), the empty model's diagnosis is
    `undetermined`, the reason naming what is missing (the controller's gains, the recorded
    output), exit 0, never 2."""
    from feedaxis.measurement import tracking

    monkeypatch.setattr(tracking, "loop_start", lambda *args, **kwargs: None)
    record = cascade_loop(exciting, 1.0, "P-P")
    case = read_case(write_cascade_case(tmp_path / "case", record, "P-P", 1))
    found = diagnose(case, Model())
    assert found.verdict == "undetermined" and not found.candidates
    assert "control_V" in found.undetermined_reason and "gains" in found.undetermined_reason
    assert main(["diagnose", str(case.folder)]) == 0
    assert "undetermined" in capsys.readouterr().out

