"""The four FMUs co-simulated as one axis by the project's master (feedaxis.cosim)."""
import signal
from dataclasses import replace

import numpy as np
import pytest

from feedaxis.cosim.master import Master, SimulationInterrupted
from feedaxis.cosim.system import Component, Connection, default_axis, markdown_tables
from scenarios import direct_axis

STOP_S = 3.0


def axis_inputs(system, stop_s=STOP_S):
    """A fast stroke back and forth (heats the screw), a cutting-like force, ambient drift."""
    t = np.arange(int(round(stop_s / system.macro_step_s))) * system.macro_step_s
    return {"position_ref_mm": 40.0 * np.sin(2 * np.pi * 0.5 * t) + 3.0 * (t > 2.0),
            "disturbance_N": 50.0 * np.sin(2 * np.pi * 30.0 * t) * (t > 1.0),
            "ambient_C": 20.0 + 0.5 * t}


@pytest.fixture(scope="module")
def master(fmu_paths):
    with Master(default_axis(), fmu_paths) as running:
        yield running


def test_cosimulation_agrees_with_the_physics_composed_directly(master):
    """Tolerance 1e-9 relative: no connection lag to allow for.

    The master steps the components in dependency order within each macro step, so the
    error FMUs see the servo's position of the same instant (no one-step lag), and the
    direct composition follows the same multi-rate sampling (thermal every 100 macro steps,
    inputs of the macro step that ends its step, outputs held). Both run the same
    floating-point operations, so they agree to rounding.
    """
    system = master.system
    inputs = axis_inputs(system)
    result = master.run(STOP_S, inputs)
    expected = direct_axis(system, inputs)
    assert result.size == inputs["position_ref_mm"].size + 1
    np.testing.assert_allclose(result["time"][1:], (np.arange(result.size - 1) + 1) * 1e-3)
    for name, values in expected.items():
        scale = np.max(np.abs(values))
        assert scale > 0, f"{name} never moves: the scenario tests nothing"
        np.testing.assert_allclose(result[name][1:], values, rtol=1e-9, atol=1e-9 * scale,
                                   err_msg=name)
    table = result["NpidServo.position_mm"] + 1e-3 * result["positioning_error_um"]
    np.testing.assert_allclose(result["table_position_mm"], table, rtol=1e-12)


def test_thermal_component_steps_every_100_macro_steps_and_holds(master):
    result = master.run(1.0, axis_inputs(master.system, 1.0))
    changes = np.flatnonzero(np.diff(result["ThermalScrew.elongation_um"])) + 1
    assert changes.size > 5
    assert set(changes % 100) == {0}


def test_parameters_overridden_per_run(master):
    inputs = axis_inputs(master.system, 1.0)
    npid = master.run(1.0, inputs, parameters={"NpidServo": {"nonlinear": True}})
    expected = direct_axis(master.system.with_parameters({"NpidServo": {"nonlinear": True}}),
                           inputs)
    np.testing.assert_allclose(npid["NpidServo.tracking_error_mm"][1:],
                               expected["NpidServo.tracking_error_mm"], rtol=1e-9, atol=1e-12)
    pid = master.run(1.0, inputs)
    assert not np.allclose(pid["NpidServo.tracking_error_mm"], npid["NpidServo.tracking_error_mm"])


def test_output_interval_and_record_times(master):
    result = master.run(0.5, {"position_ref_mm": 1.0}, output_interval_s=0.1,
                        record_at_s=[0.123])
    np.testing.assert_allclose(result["time"], [0, 0.1, 0.123, 0.2, 0.3, 0.4, 0.5])


def test_ctrl_c_stops_cleanly_with_the_rows_computed(master):
    def press_ctrl_c(done_steps, total_steps):
        if done_steps == 1000:
            signal.raise_signal(signal.SIGINT)

    before = signal.getsignal(signal.SIGINT)  # SIG_IGN when the suite runs under nohup ... &
    with pytest.raises(SimulationInterrupted) as stopped:
        master.run(5.0, {"position_ref_mm": 1.0}, progress=press_ctrl_c)
    partial = stopped.value.partial
    assert partial["time"][-1] == pytest.approx(1.0)
    assert np.isfinite(partial["table_position_mm"]).all()
    assert signal.getsignal(signal.SIGINT) is before


def test_ctrl_c_while_the_fmus_are_instantiated_stops_cleanly(master, monkeypatch):
    instantiate = master._instantiate

    def instantiate_then_ctrl_c(*args):
        entry = instantiate(*args)
        signal.raise_signal(signal.SIGINT)
        return entry

    monkeypatch.setattr(master, "_instantiate", instantiate_then_ctrl_c)
    with pytest.raises(SimulationInterrupted) as stopped:
        master.run(1.0, {"position_ref_mm": 1.0})
    assert stopped.value.partial["time"].tolist() == [0.0]


def test_sigint_ignored_by_the_parent_is_restored_after_a_run(master):
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        master.run(0.01, {"position_ref_mm": 1.0})
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.mark.parametrize("change, message", [
    (lambda s: s.with_steps(ThermalScrew=0.1005), "whole multiple"),
    (lambda s: s.with_parameters({"Spindle": {}}), "no component 'Spindle'"),
])
def test_bad_system_is_refused(change, message):
    with pytest.raises(ValueError, match=message):
        change(default_axis())


@pytest.mark.parametrize("extra, message", [
    (Connection("Echo.error_um", "Echo.position_mm"), "algebraic loop: Echo"),
    (Connection("GeometricError.error_um", "Echo.position_mm"), None),
    (Connection("position_ref_mm", "StepperError.position_mm"), "more than one connection"),
])
def test_connections_are_checked(extra, message):
    system = default_axis()
    build = lambda: type(system)(system.name, system.macro_step_s, system.inputs,
                                 system.components + (Component("Echo", "StepperError", 1e-3),),
                                 system.connections + (extra,), system.outputs)
    if message is None:
        assert [c.name for c in build().ordered_components()][-1] == "Echo"
    else:
        with pytest.raises(ValueError, match=message):
            build()


@pytest.mark.parametrize("kwargs, message", [
    ({"inputs": {"spindle_rpm": 1.0}}, "no system input spindle_rpm"),
    ({"parameters": {"NpidServo": {"gain": 1.0}}}, "NpidServo: no parameter gain"),
    ({"inputs": {"ambient_C": np.zeros(10)}}, "input ambient_C: 10 values for 100"),
    ({"output_interval_s": 0.0015}, "whole number of macro steps"),
])
def test_bad_run_arguments_are_refused(master, kwargs, message):
    with pytest.raises(ValueError, match=message):
        master.run(0.1, **kwargs)


def test_markdown_tables_list_every_component_and_connection():
    system = default_axis()
    tables = markdown_tables(system)
    for component in system.components:
        assert f"| `{component.name}` |" in tables
    for connection in system.connections:
        assert f"| `{connection.source}` | `{connection.target}` |" in tables
    assert "100 ms (every 100 macro steps)" in tables


def test_the_master_loop_unpacks_its_plan_by_the_plan_entry_fields():
    """The macro-step loop unpacks each PlanEntry by position (the fastest access); the
    names it unpacks must be the fields, in order."""
    import inspect
    import re

    from feedaxis.cosim.master import PlanEntry, PythonSteps

    unpacked = re.search(r"for \(([^)]*)\) in plan:",
                         inspect.getsource(PythonSteps.__call__)).group(1)
    assert tuple(n.strip() for n in unpacked.split(",")) == PlanEntry._fields


def test_inputs_read_in_place_and_copied_give_the_same_run(master, fmu_paths, monkeypatch):
    """A component whose inputs sit side by side in the signal array reads them there
    (GeometricError: the servo's position and velocity); listed in the other order they
    are copied into an input buffer first. Both runs give the same numbers."""
    system = master.system
    inputs = axis_inputs(system, 1.0)
    in_place = master.run(1.0, inputs)
    geometric = [c for c in system.connections if c.target.startswith("GeometricError.")]
    others = [c for c in system.connections if c not in geometric]
    swapped = replace(system, connections=tuple(others + geometric[::-1]))
    plan = {}
    instantiate = Master._instantiate

    def recorded(self, *args):
        entry = instantiate(self, *args)
        plan[entry.name] = entry
        return entry

    monkeypatch.setattr(Master, "_instantiate", recorded)
    with Master(swapped, fmu_paths) as copying:
        copied = copying.run(1.0, inputs)
    position, velocity = (copying.signal_names.index(f"NpidServo.{name}")
                          for name in ("position_mm", "velocity_mm_s"))
    assert plan["GeometricError"].copies == ((0, velocity), (1, position))
    assert plan["StepperError"].copies == ()  # its one input read in place
    for name in in_place.dtype.names:
        np.testing.assert_array_equal(copied[name], in_place[name], err_msg=name)
