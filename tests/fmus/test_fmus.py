"""The four FMUs as products: valid, faithful to the physics, robust, restorable."""
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu, supported_platforms
from fmpy.fmi1 import FMICallException
from fmpy.util import read_csv
from fmpy.validation import validate_fmu

from feedaxis.cosim.fmu_runner import run_fmu
from feedaxis.fmu_build import FMU_NAMES
from scenarios import N_STEPS, OUTPUTS, PARAMETERS, STEP_SIZE_S, direct, scripted_inputs

FMU_SOURCES = Path(__file__).resolve().parents[2] / "fmus"
# The host layer returns fmi2Error for any call during which the slave logged an error.
ERROR = 3


def run_scripted(loaded, name, parameters=None, instance_name="feedaxis"):
    return run_fmu(loaded, STEP_SIZE_S[name], N_STEPS[name], scripted_inputs(name),
                   PARAMETERS[name] if parameters is None else parameters, OUTPUTS[name],
                   instance_name)


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmu_passes_fmpy_validation(fmu_paths, name):
    assert validate_fmu(str(fmu_paths[name])) == []


ELF_X86_64 = (2, 62)  # an ELF file's class (64-bit) and machine (x86-64)


def assert_carries_one_platform(fmu_path, platform):
    """The FMU's binaries/ holds the one folder ``platform`` (FMI 2.0's linux64 or FMI 3.0's
    x86_64-linux), which fmpy lists as its only platform, and every binary it carries
    anywhere is an x86-64 ELF: no library of another platform rides along."""
    assert supported_platforms(str(fmu_path)) == ["linux64"]  # fmpy's name for both folders
    with zipfile.ZipFile(fmu_path) as archive:
        names = [n for n in archive.namelist() if not n.endswith("/")]
        assert {n.split("/")[1] for n in names if n.startswith("binaries/")} == {platform}
        assert not [n for n in names if n.endswith((".dll", ".dylib"))]
        heads = {n: archive.open(n).read(20) for n in names}
    elves = {n: (head[4], int.from_bytes(head[18:20], "little")) for n, head in heads.items()
             if head.startswith(b"\x7fELF")}
    assert elves and set(elves.values()) == {ELF_X86_64}


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmu_declares_only_the_platform_it_carries(fmu_paths, name):
    """linux64 alone: not pythonfmu's stock win64 library."""
    assert_carries_one_platform(fmu_paths[name], "linux64")


@pytest.mark.parametrize("name", FMU_NAMES)
def test_model_description_declares_units_and_state(loaded_fmus, name):
    description = loaded_fmus[name].description
    assert description.coSimulation.canGetAndSetFMUstate
    for variable in description.modelVariables:
        assert variable.description, variable.name
        if variable.type == "Real" and variable.causality in ("input", "output"):
            assert variable.unit, variable.name


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmu_matches_cross_check_reference(fmu_paths, name):
    folder = FMU_SOURCES / name
    options = dict(line.split(", ") for line in (folder / f"{name}_ref.opt").read_text().splitlines())
    reference = read_csv(folder / f"{name}_ref.csv")
    result = simulate_fmu(str(fmu_paths[name]), stop_time=float(options["StopTime"]),
                          step_size=float(options["StepSize"]),
                          output_interval=float(options["StepSize"]),
                          input=read_csv(folder / f"{name}_in.csv"),
                          output=list(OUTPUTS[name]))
    assert len(result) == len(reference)
    for output in OUTPUTS[name]:
        np.testing.assert_allclose(result[output], reference[output], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmu_reproduces_physics_called_directly(loaded_fmus, name):
    result = run_scripted(loaded_fmus[name], name)
    expected = direct(name, scripted_inputs(name), PARAMETERS[name])[1:]
    for i, output in enumerate(OUTPUTS[name]):
        scale = np.max(np.abs(expected[:, i]))
        assert scale > 0, f"{name}.{output} never moves: the scenario tests nothing"
        np.testing.assert_allclose(result[output], expected[:, i], rtol=1e-9, atol=1e-9 * scale)


def test_all_four_fmus_run_together_and_repeat_identically(loaded_fmus):
    first = {name: run_scripted(loaded_fmus[name], name) for name in FMU_NAMES}
    for cycle in range(100):
        for name in FMU_NAMES:
            slave = loaded_fmus[name].instantiate(f"{name}_{cycle}")
            slave.freeInstance()
    again = {name: run_scripted(loaded_fmus[name], name) for name in FMU_NAMES}
    for name in FMU_NAMES:
        for output in OUTPUTS[name]:
            np.testing.assert_array_equal(again[name][output], first[name][output])


@pytest.mark.parametrize("name", FMU_NAMES)
def test_get_and_set_state_restores_internal_state(loaded_fmus, name):
    loaded = loaded_fmus[name]
    inputs = scripted_inputs(name)
    h = STEP_SIZE_S[name]
    slave = loaded.instantiate("state")
    loaded.set_values(slave, PARAMETERS[name])
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()

    def advance(first_step, n_steps):
        for k in range(first_step, first_step + n_steps):
            loaded.set_values(slave, {n: v[k].item() for n, v in inputs.items()})
            slave.doStep(k * h, h)
        return loaded.get_reals(slave, OUTPUTS[name])

    advance(0, 200)
    saved = slave.getFMUstate()
    after_save = advance(200, 100)
    advance(300, 150)
    slave.setFMUstate(saved)
    restored = advance(200, 100)
    serialized = slave.serializeFMUstate(saved)
    slave.setFMUstate(slave.deSerializeFMUstate(serialized))
    deserialized = advance(200, 100)
    slave.freeFMUstate(saved)
    slave.freeInstance()
    assert restored == after_save
    assert deserialized == after_save


BAD_PARAMETERS = [
    ("GeometricError", {"lead_mm": 0.0}, "lead_mm"),
    ("StepperError", {"lead_mm": -1.0}, "lead_mm"),
    ("ThermalScrew", {"diameter_m": 0.0}, "diameter_m"),
    ("ThermalScrew", {"time_step_s": 0.0}, "time_step_s"),
    ("NpidServo", {"time_step_s": -1e-4}, "time_step_s"),
    ("NpidServo", {"e_max_mm": 0.0}, "e_max_mm"),
    ("GeometricError", {"support": "floating"}, "support"),
    # values each in range whose derived quantities are beyond a float's (issue 26)
    ("NpidServo", {"time_step_s": 1e-300}, "time_step_s"),
    ("NpidServo", {"plant_stiffness_per_s2": 1e300}, "plant_stiffness_per_s2"),
    ("NpidServo", {"force_constant_N_per_V": 5e-324}, "force_constant_N_per_V"),
    ("GeometricError", {"length_m": 1e300}, "length_m"),
    ("GeometricError", {"diameter_m": 1e-300}, "diameter_m"),
    ("GeometricError", {"diameter_m": 1e300}, "diameter_m"),
    ("GeometricError", {"youngs_modulus_Pa": 5e-324}, "youngs_modulus_Pa"),
    ("StepperError", {"lead_mm": 5e-324}, "lead_mm"),
    ("ThermalScrew", {"length_m": 1e300}, "length_m"),
    ("ThermalScrew", {"diameter_m": 1e300}, "diameter_m"),
    ("ThermalScrew", {"density_kg_m3": 5e-324}, "density_kg_m3"),
    ("ThermalScrew", {"nut_length_m": 5e-324}, "nut_length_m"),
    ("ThermalScrew", {"time_step_s": 5e-324}, "time_step_s"),
]


@pytest.mark.parametrize("name, parameters, named", BAD_PARAMETERS)
def test_bad_parameter_gives_fmi_error_with_message(loaded_fmus, capsys, name, parameters, named):
    with pytest.raises(FMICallException) as failure:
        run_fmu(loaded_fmus[name], STEP_SIZE_S[name], 3, scripted_inputs(name), parameters,
                OUTPUTS[name])
    assert failure.value.status == ERROR
    errors = [line for line in capsys.readouterr().out.splitlines() if "[ERROR]" in line]
    assert len(errors) == 1 and named in errors[0] and "internal error" not in errors[0]
    assert np.isfinite(run_scripted(loaded_fmus[name], name)[OUTPUTS[name][0]]).all()


def initialised(loaded, instance_name="refusals"):
    slave = loaded.instantiate(instance_name)
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave


def refused(call, capsys):
    """The one error message of a call that must end in fmi2Error (issue 26: it was
    fmi2Fatal, which leaves the instance dead)."""
    with pytest.raises(FMICallException) as failure:
        call()
    assert failure.value.status == ERROR
    errors = [line for line in capsys.readouterr().out.splitlines() if "[ERROR]" in line]
    assert len(errors) == 1, errors
    return errors[0]


@pytest.mark.parametrize("name", FMU_NAMES)
def test_an_unknown_or_mistyped_value_reference_is_an_error_not_fatal(loaded_fmus, capsys, name):
    """fmi2Get/SetX with a reference that is no variable, or a variable of another type: an
    error naming the reference, which puts the instance into the error state (FMI 2.0: any
    fmi2Error does); fmi2SetFMUstate with the state saved before takes it out, and it steps."""
    loaded = loaded_fmus[name]
    slave = initialised(loaded)
    healthy = slave.getFMUstate()
    real = loaded.variables[OUTPUTS[name][0]].valueReference
    calls = {
        "fmi2GetReal: value reference 9999 is not a variable of this FMU":
            lambda: slave.getReal([9999]),
        "fmi2SetReal: value reference 9999 is not": lambda: slave.setReal([9999], [1.0]),
        f"value reference {real} is {OUTPUTS[name][0]}, a Real variable, not an Integer":
            lambda: slave.getInteger([real]),
        "not a Boolean": lambda: slave.setBoolean([real], [True]),
        "fmi2GetString: value reference 9999": lambda: slave.getString([9999]),
    }
    try:
        for message, call in calls.items():
            assert message in refused(call, capsys)
            assert "not allowed in the error state" in refused(
                lambda: slave.doStep(0.0, STEP_SIZE_S[name]), capsys)
            slave.setFMUstate(healthy)
        slave.doStep(0.0, STEP_SIZE_S[name])
        assert np.isfinite(loaded.get_reals(slave, OUTPUTS[name])).all()
    finally:
        slave.freeFMUstate(healthy)
        slave.freeInstance()


@pytest.mark.parametrize("name", FMU_NAMES)
def test_a_corrupt_state_buffer_is_an_error_and_a_good_one_still_restores(loaded_fmus, capsys,
                                                                           name):
    """fmi2DeSerializeFMUstate of an empty, 1-byte, truncated or foreign buffer, one with a
    wrong type or a changed fixed parameter: an error saying why (was fmi2Fatal); then the
    instance's own state still restores and the run continues as saved."""
    loaded = loaded_fmus[name]
    other = loaded_fmus[FMU_NAMES[(FMU_NAMES.index(name) + 1) % len(FMU_NAMES)]]
    foreign_slave = initialised(other, "foreign")
    foreign = foreign_slave.serializeFMUstate(foreign_slave.getFMUstate())
    foreign_slave.freeInstance()
    slave = initialised(loaded)
    try:
        good = slave.serializeFMUstate(slave.getFMUstate())
        state = json.loads(good)
        output = OUTPUTS[name][0]
        fixed = next(v.name for v in loaded.description.modelVariables
                     if v.variability == "fixed" and v.type == "Real")
        corrupt = {
            b"": "an empty buffer is not a state", b"{": "not a serialised state",
            b"x": "not a serialised state", good[:len(good) // 2]: "not a serialised state",
            b"[1, 2]": "a JSON list", b"[" * 100000: "not a serialised state",
            foreign: "not a state of this FMU",
            json.dumps({**state, output: "text"}).encode(): f"{output} holds 'text', not a Real",
            json.dumps({**state, fixed: state[fixed] * 2 + 1}).encode():
                f"fixed parameter {fixed} is",
        }
        for data, reason in corrupt.items():
            assert reason in refused(lambda: slave.deSerializeFMUstate(data), capsys)
        slave.setFMUstate(slave.deSerializeFMUstate(good))  # out of the error state
        h = STEP_SIZE_S[name]
        slave.doStep(0.0, h)
        after_one = loaded.get_reals(slave, OUTPUTS[name])
        slave.setFMUstate(slave.deSerializeFMUstate(good))
        slave.doStep(0.0, h)
        assert loaded.get_reals(slave, OUTPUTS[name]) == after_one
    finally:
        slave.freeInstance()


def test_a_state_whose_model_part_does_not_restore_is_refused_and_rolled_back(loaded_fmus,
                                                                              capsys):
    """A well-formed state whose model part the physics cannot take (a temperature field of
    text): fmi2SetFMUstate is an error naming it, and the instance keeps its own state."""
    loaded = loaded_fmus["ThermalScrew"]
    slave = initialised(loaded)
    try:
        slave.setReal([loaded.variables["velocity_mm_s"].valueReference], [100.0])
        slave.doStep(0.0, 10.0)
        before = loaded.get_reals(slave, OUTPUTS["ThermalScrew"])
        state = json.loads(slave.serializeFMUstate(slave.getFMUstate()))
        state["model_state"] = {"rise_K": "text"}
        bad = slave.deSerializeFMUstate(json.dumps(state).encode())
        assert "fmi2SetFMUstate refused, the instance is unchanged: its model state does not " \
            "restore" in refused(lambda: slave.setFMUstate(bad), capsys)
        assert loaded.get_reals(slave, OUTPUTS["ThermalScrew"]) == before
    finally:
        slave.freeInstance()


@pytest.mark.parametrize("engagement", [2.0, "text", None])
def test_a_backlash_engagement_outside_the_play_is_refused(loaded_fmus, capsys, engagement):
    """GeometricError's model state is the nut's engagement in its play, -1 to +1: a state
    with another is refused and the instance keeps its own."""
    loaded = loaded_fmus["GeometricError"]
    slave = initialised(loaded)
    try:
        before = loaded.get_reals(slave, OUTPUTS["GeometricError"])
        state = json.loads(slave.serializeFMUstate(slave.getFMUstate()))
        state["model_state"] = {"engagement": engagement}
        bad = slave.deSerializeFMUstate(json.dumps(state).encode())
        assert "engagement must be a number from -1 to 1" in refused(
            lambda: slave.setFMUstate(bad), capsys)
        assert loaded.get_reals(slave, OUTPUTS["GeometricError"]) == before
    finally:
        slave.freeInstance()


@pytest.mark.parametrize("name", [n for n in FMU_NAMES if scripted_inputs(n)])
def test_nan_input_gives_fmi_error_with_message(loaded_fmus, capsys, name):
    """A NaN input is refused where it is set (the host layer checks every Real it is given;
    a build without the layer refuses it at the next doStep, the slave's check)."""
    inputs = scripted_inputs(name)
    first_input = next(iter(inputs))
    inputs[first_input] = inputs[first_input].astype(float)
    inputs[first_input][2] = np.nan
    with pytest.raises(FMICallException) as failure:
        run_fmu(loaded_fmus[name], STEP_SIZE_S[name], 5, inputs, {}, OUTPUTS[name])
    assert failure.value.status == ERROR
    assert f"[ERROR] feedaxis: fmi2SetReal: input {first_input} must be finite, got nan" \
        in capsys.readouterr().out


def test_finite_inputs_whose_sum_overflows_still_step(loaded_fmus, capsys):
    """The exchange checks all inputs by their sum at once: finite inputs summing to inf
    take the slow path, which finds nothing wrong and steps."""
    result = run_fmu(loaded_fmus["GeometricError"], 0.01, 2,
                     {"position_mm": [1e307, 1e307], "velocity_mm_s": [1.79e308, 1.79e308]},
                     {"sag_enabled": False}, ("error_um",))
    assert np.isfinite(result["error_um"]).all()
    assert "[ERROR]" not in capsys.readouterr().out


def test_zero_communication_step_is_refused(loaded_fmus, capsys):
    with pytest.raises(FMICallException) as failure:
        run_fmu(loaded_fmus["StepperError"], 0.0, 2, {"position_mm": [0.0, 0.1]}, {}, ("error_um",))
    assert failure.value.status == ERROR
    assert "communication step size must be finite and > 0" in capsys.readouterr().out


def build_without(monkeypatch, tmp_path, name, module, check, error, warning):
    """Build FMU ``name`` with ``module.check`` saying what is missing: ``error`` under CI,
    else ``warning`` and the FMU's path."""
    from feedaxis import fmu_build

    monkeypatch.setattr(module, check, lambda: "missing (test)")
    monkeypatch.setenv("CI", "true")
    with pytest.raises(error, match="CI requires"):
        fmu_build.build_fmu(name, tmp_path / "ci")
    monkeypatch.delenv("CI")
    with pytest.warns(UserWarning, match=warning):
        return fmu_build.build_fmu(name, tmp_path)


def test_without_a_compiler_the_fmus_still_run_in_python_hosts(tmp_path, monkeypatch,
                                                                loaded_fmus):
    """A bare pip machine (no cc, no Python headers): pythonfmu's own library, a warning,
    and the same results in fmpy as the FMU with the host layer; under CI it is an error."""
    from feedaxis import fmu_build

    path = build_without(monkeypatch, tmp_path, "StepperError", fmu_build, "host_layer_missing",
                         fmu_build.HostLayerUnavailable, "Python hosts only")
    with zipfile.ZipFile(path) as archive:
        assert "binaries/linux64/libpythonfmu-export.so" not in archive.namelist()
    from feedaxis.cosim.fmu_runner import LoadedFmu

    python_only = LoadedFmu(path)
    try:
        expected = run_scripted(loaded_fmus["StepperError"], "StepperError")
        got = run_scripted(python_only, "StepperError")
        for output in OUTPUTS["StepperError"]:
            np.testing.assert_array_equal(got[output], expected[output])
    finally:
        python_only.close()


# Runs the NPID scenario of one FMU in a fresh process (an FMU's package is imported once per
# process: a second build of NpidServo in this one would run the first one's code).
SCENARIO = """
import json, sys
sys.path.insert(0, sys.argv[2])
from feedaxis.cosim.fmu_runner import run_fmu
from scenarios import N_STEPS, OUTPUTS, PARAMETERS, STEP_SIZE_S, scripted_inputs
result = run_fmu(sys.argv[1], STEP_SIZE_S["NpidServo"], N_STEPS["NpidServo"],
                 scripted_inputs("NpidServo"), PARAMETERS["NpidServo"], OUTPUTS["NpidServo"])
print(json.dumps({name: result[name].tolist() for name in OUTPUTS["NpidServo"]}))
"""


def npid_scenario_in_fresh_process(fmu_path):
    """(outputs by name, what the FMU logged) of the NPID scenario in a new process."""
    run = subprocess.run([sys.executable, "-c", SCENARIO, str(fmu_path),
                          str(Path(__file__).resolve().parents[1])],
                         capture_output=True, text=True, check=True)
    *log, outputs = run.stdout.strip().splitlines()
    return {name: np.array(values) for name, values in json.loads(outputs).items()}, log


def kernels_in(fmu_path):
    with zipfile.ZipFile(fmu_path) as archive:
        return [name for name in archive.namelist() if "/physics/step_kernel" in name]


def test_servo_fmu_steps_the_compiled_loop(fmu_paths, compiled_servo_loop):
    """NpidServo carries run_loop compiled ahead of time; NPID through it equals the physics
    stepped by Python (test_fmu_reproduces_physics_called_directly runs NPID in-process)."""
    assert len(kernels_in(fmu_paths["NpidServo"])) == 1
    outputs, log = npid_scenario_in_fresh_process(fmu_paths["NpidServo"])
    expected = direct("NpidServo", scripted_inputs("NpidServo"), PARAMETERS["NpidServo"])[1:]
    np.testing.assert_allclose(outputs["position_mm"], expected[:, 0], rtol=0, atol=1e-12)
    assert not log


def test_without_the_servo_kernel_the_fmu_steps_python_with_the_same_results(
        tmp_path, monkeypatch, fmu_paths):
    """Where the kernel cannot be compiled (no numba.pycc, no compiler): a warning at the build,
    no kernel in the FMU, the Python loop with the same results; under CI it is an error."""
    from feedaxis import kernel_build

    path = build_without(monkeypatch, tmp_path, "NpidServo", kernel_build, "kernel_missing",
                         kernel_build.KernelUnavailable, "the FMUs step in Python")
    assert kernels_in(path) == []
    python_loop, log = npid_scenario_in_fresh_process(path)
    compiled, _ = npid_scenario_in_fresh_process(fmu_paths["NpidServo"])
    for output in OUTPUTS["NpidServo"]:
        np.testing.assert_allclose(python_loop[output], compiled[output], rtol=0, atol=1e-12)
    assert not log


def test_a_kernel_that_does_not_load_is_a_warning_and_the_python_loop(tmp_path, fmu_paths):
    """An FMU moved to a Python whose ABI the kernel does not fit: the import fails, the FMU
    says so once (logStatusWarning) and steps the Python loop."""
    broken = tmp_path / "NpidServo.fmu"
    with zipfile.ZipFile(fmu_paths["NpidServo"]) as source, zipfile.ZipFile(broken, "w") as fmu:
        for entry in source.infolist():
            data = source.read(entry)
            fmu.writestr(entry, b"not a library" if "step_kernel" in entry.filename else data)
    outputs, log = npid_scenario_in_fresh_process(broken)
    expected, _ = npid_scenario_in_fresh_process(fmu_paths["NpidServo"])
    np.testing.assert_allclose(outputs["position_mm"], expected["position_mm"], rtol=0, atol=1e-12)
    assert len(log) == 1 and "the compiled step does not load" in log[0]


@pytest.mark.parametrize("name", FMU_NAMES)
def test_every_python_file_of_an_fmu_carries_its_own_bytecode(fmu_paths, name):
    """Beside each Python file of the resources the FMU carries that file's bytecode for
    this Python, checked against the source's hash (PEP 552 flags 0b11): an unpacked FMU
    is imported without compiling, and an edited file is compiled again."""
    import importlib.util
    import marshal

    with zipfile.ZipFile(fmu_paths[name]) as archive:
        entries = {n: archive.read(n) for n in archive.namelist()}
    sources = [n for n in entries if n.startswith("resources/") and n.endswith(".py")]
    assert len(sources) > 20
    for source in sources:
        folder, _, file_name = source.rpartition("/")
        pyc = entries[f"{folder}/__pycache__/{file_name[:-3]}.{sys.implementation.cache_tag}.pyc"]
        assert pyc[:4] == importlib.util.MAGIC_NUMBER
        assert int.from_bytes(pyc[4:8], "little") == 0b11, source
        assert pyc[8:16] == importlib.util.source_hash(entries[source]), source
        assert marshal.loads(pyc[16:]) == compile(entries[source], source, "exec",
                                                  dont_inherit=True), source
