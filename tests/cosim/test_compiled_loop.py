"""The master's compiled macro-step loop (feedaxis.cosim.compiled_loop) against its Python
loop (master.PythonSteps): the same FMU calls on the same plan, so the same recorded numbers
to the bit, the same failure, stop and progress; the Python loop where no compiler exists."""
import logging
import signal

import numpy as np
import pytest

from conftest import unavailable
from feedaxis import toolchain
from feedaxis.cosim.compiled_loop import loop_library
from feedaxis.cosim.master import FmuStepError, Master, SimulationInterrupted
from feedaxis.cosim.system import default_axis

MODES = {"PID": {}, "NPID": {"NpidServo": {"nonlinear": True}},
         "friction": {"NpidServo": {"friction_N": 40.0, "damping_N_s_per_mm": 0.02}}}


@pytest.fixture(autouse=True)
def fresh_library():
    """Each test finds the library as the machine gives it, and leaves no patched answer."""
    loop_library.cache_clear()
    yield
    loop_library.cache_clear()


def compiled_available():
    library, missing = loop_library()
    if library is None:
        unavailable(f"the compiled co-simulation loop is not available: {missing}")


def seeded_inputs(seed, n_steps, h=1e-3):
    """Random strokes, a force given as a function of time, an ambient drift (arrays)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_steps) * h
    amplitude_mm, frequency_hz = rng.uniform(5.0, 40.0), rng.uniform(0.2, 2.0)
    force_N, force_hz = rng.uniform(10.0, 80.0), rng.uniform(5.0, 40.0)
    return {"position_ref_mm": amplitude_mm * np.sin(2 * np.pi * frequency_hz * t)
            + rng.normal(0.0, 0.01, n_steps).cumsum(),
            "disturbance_N": lambda t_s: force_N * np.sin(2 * np.pi * force_hz * t_s),
            "ambient_C": 20.0 + rng.uniform(0.0, 1.0) * t}


def both_ways(system, fmu_paths, run):
    """``run(master)`` with the compiled loop and with the Python loop: (what each gave or
    raised, why the master steps in Python or None) in that order."""
    outcomes = []
    for compiled in (True, False):
        with Master(system, fmu_paths, compiled_loop=compiled) as master:
            try:
                outcome = run(master)
            except (FmuStepError, SimulationInterrupted) as error:
                outcome = error
            outcomes.append((outcome, master.loop_missing))
    assert outcomes[0][1] is None
    assert outcomes[1][1] == "the Python loop was asked for"
    return outcomes


def assert_same_rows(first, second):
    assert first.dtype.names == second.dtype.names
    assert first.size == second.size
    for name in first.dtype.names:
        assert np.array_equal(first[name], second[name]), name
        assert first[name].tobytes() == second[name].tobytes(), name  # to the bit (-0.0, NaN)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("seed, steps, grid", [
    (1, {}, {}),  # every macro step recorded, the thermal screw every 100
    (2, {"GeometricError": 3e-3, "StepperError": 2e-3}, {"output_interval_s": 0.007}),
    (3, {"ThermalScrew": 0.05}, {"output_interval_s": 0.004, "record_at_s": [0.0015, 1.2345]}),
])
def test_compiled_and_python_loops_record_the_same_bits(fmu_paths, mode, seed, steps, grid):
    compiled_available()
    system = default_axis().with_steps(**steps)
    stop_s = 2.5
    inputs = seeded_inputs(seed, int(round(stop_s / system.macro_step_s)))
    (compiled, _), (python, _) = both_ways(
        system, fmu_paths, lambda master: master.run(stop_s, inputs, MODES[mode], **grid))
    assert_same_rows(compiled, python)
    assert np.ptp(compiled["positioning_error_um"]) > 0.1  # the axis moved
    assert np.ptp(compiled["ThermalScrew.elongation_um"]) > 0  # the slow component stepped
    if grid:
        assert compiled.size < 0.3 * stop_s / system.macro_step_s  # the grid skipped steps


def test_a_failing_fmu_gives_the_same_error_both_ways(fmu_paths, capfd):
    """A reference that turns NaN in the middle of a chunk: NpidServo refuses it."""
    compiled_available()
    reference = np.sin(np.arange(2000) * 1e-3)
    reference[1234] = np.nan
    system = default_axis().with_steps(GeometricError=2e-3)
    (compiled, _), (python, _) = both_ways(
        system, fmu_paths, lambda master: master.run(2.0, {"position_ref_mm": reference}))
    assert isinstance(compiled, FmuStepError) and isinstance(python, FmuStepError)
    assert str(compiled) == str(python) == (
        "NpidServo failed in the step ending at t = 1.235 s (its log above says why)")
    assert capfd.readouterr().out.count("position_ref_mm must be finite, got nan") == 2


def test_stop_and_progress_behave_the_same_both_ways(fmu_paths):
    compiled_available()
    calls = {}

    def run(master):
        told = calls.setdefault(len(calls), [])

        def progress(done_steps, total_steps):
            told.append((done_steps, total_steps))
            if done_steps == 2000:
                signal.raise_signal(signal.SIGINT)

        return master.run(5.0, seeded_inputs(4, 5000), progress=progress)

    (compiled, _), (python, _) = both_ways(default_axis(), fmu_paths, run)
    assert isinstance(compiled, SimulationInterrupted) and isinstance(python, SimulationInterrupted)
    assert calls[0] == calls[1] == [(1000, 5000), (2000, 5000)]
    assert compiled.partial["time"][-1] == pytest.approx(2.0)
    assert_same_rows(compiled.partial, python.partial)


def test_progress_counts_every_chunk_both_ways(fmu_paths):
    compiled_available()
    calls = []
    both_ways(default_axis(), fmu_paths, lambda master: master.run(
        2.5, {"position_ref_mm": 1.0}, progress=lambda *done: calls.append(done)))
    assert calls == [(1000, 2500), (2000, 2500), (2500, 2500)] * 2


def test_profiled_compiled_loop_times_the_fmu_calls(fmu_paths):
    compiled_available()
    with Master(default_axis(), fmu_paths) as master:
        master.run(0.5, {"position_ref_mm": 1.0}, profile=True)
    timing = master.timing
    assert timing.loop == "compiled"
    assert 0 < timing.fmu_s < timing.loop_s
    assert timing.timer_s > 0
    assert 0 < timing.overhead_fraction < 1


def test_without_a_compiler_the_python_loop_runs_and_says_why(fmu_paths, monkeypatch,
                                                                   caplog):
    inputs = seeded_inputs(5, 1500)
    with Master(default_axis(), fmu_paths) as master:
        expected = master.run(1.5, inputs, MODES["NPID"], output_interval_s=0.003)
    loop_library.cache_clear()
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setattr(toolchain.shutil, "which", lambda name: None)
    with caplog.at_level(logging.DEBUG, logger="feedaxis.cosim.compiled_loop"):
        with Master(default_axis(), fmu_paths) as master:
            result = master.run(1.5, inputs, MODES["NPID"], output_interval_s=0.003)
    assert master.library is None
    assert master.timing.loop == "python (no C compiler (cc or gcc, or set CC))"
    assert "steps in Python: no C compiler" in caplog.text
    assert_same_rows(result, expected)


def test_a_failed_build_falls_back_to_the_python_loop(fmu_paths, monkeypatch, tmp_path):
    compiled_available()
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setenv("CC", "false")  # a "compiler" that fails
    loop_library.cache_clear()
    with Master(default_axis(), fmu_paths) as master:
        master.run(0.1, {"position_ref_mm": 1.0})
    assert master.timing.loop.startswith("python (compiling master_loop.c failed")
    assert not any(tmp_path.glob("feedaxis/master-loop-*"))  # no half-built cache left


def test_fmi3_fmus_step_the_same_in_both_loops(fmi3_paths, capfd):
    compiled_available()
    inputs = seeded_inputs(6, 1500)
    (compiled, _), (python, _) = both_ways(default_axis(), fmi3_paths,
                                           lambda master: master.run(1.5, inputs))
    assert_same_rows(compiled, python)
    reference = np.zeros(500)
    reference[321] = np.inf
    (compiled, _), (python, _) = both_ways(
        default_axis(), fmi3_paths, lambda master: master.run(0.5, {"position_ref_mm": reference}))
    assert str(compiled) == str(python) == (
        "NpidServo failed in the step ending at t = 0.322 s (its log above says why)")
