"""The FMI 3.0 co-simulation FMUs (``build-fmus --fmi 3``): valid, carrying linux64 only,
the FMI 2.0 FMUs' results to 1e-12 from the same slave and physics, and the FMI 3.0 state
machine as a host sees it through fmpy's low-level FMI 3 API (tests/fmi3_probe.py, one
process per FMU); fmi3InstantiateCoSimulation's arguments through the FMI 3.0 C host of the
tests (tests/fmi3_c_host.c). The standalone FMI 3.0 FMUs: tests/fmus/test_standalone.py."""
import json
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.util import read_csv
from fmpy.validation import validate_fmu

from feedaxis.cosim.fmu_runner import LoadedFmu, run_fmu
from feedaxis.fmu_build import FMU_NAMES
from feedaxis.fmu_fmi3 import PLATFORM
from scenarios import N_STEPS, OUTPUTS, PARAMETERS, STEP_SIZE_S, scripted_inputs
from test_fmi_contract import c_host_instantiate, check_instantiate_answer, compile_c_host
from test_fmus import assert_carries_one_platform

TESTS = Path(__file__).resolve().parents[1]
FMU_SOURCES = TESTS.parent / "fmus"
OK, ERROR = 0, 3
STATES = ("instantiated", "initialisation", "step mode", "terminated", "error")

# The FMI 3.0 standard's table of the functions callable per state (section 4.2, for a
# co-simulation FMU with hasEventMode false, no clocks and no structural parameters: Event,
# Configuration, Clock Activation and Intermediate Update Mode are never entered), written
# out here from the standard, apart from the layer's own table (fmi3_states.c).
EVERY = set(STATES)
READABLE = {"initialisation", "step mode", "terminated", "error"}
SETTABLE = {"instantiated", "initialisation", "step mode"}
TYPES = ("Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64",
         "UInt64", "Boolean", "String", "Binary")
NEVER = ("EnterEventMode", "GetClock", "SetClock", "ExitConfigurationMode",
         "GetIntervalDecimal", "GetIntervalFraction", "GetShiftDecimal", "GetShiftFraction",
         "SetIntervalDecimal", "SetIntervalFraction", "SetShiftDecimal", "SetShiftFraction",
         "EvaluateDiscreteStates", "UpdateDiscreteStates", "EnterStepMode",
         "ActivateModelPartition",
         # Model Exchange's
         "EnterContinuousTimeMode", "CompletedIntegratorStep", "SetTime", "SetContinuousStates",
         "GetContinuousStateDerivatives", "GetEventIndicators", "GetContinuousStates",
         "GetNominalsOfContinuousStates", "GetNumberOfEventIndicators",
         "GetNumberOfContinuousStates")
ALLOWED = {
    "fmi3SetDebugLogging": EVERY, "fmi3EnterInitializationMode": {"instantiated"},
    "fmi3ExitInitializationMode": {"initialisation"}, "fmi3Terminate": {"step mode"},
    "fmi3Reset": EVERY,
    **{f"fmi3Get{t}": READABLE for t in TYPES}, **{f"fmi3Set{t}": SETTABLE for t in TYPES},
    **{f"fmi3{f}": EVERY for f in ("GetFMUState", "SetFMUState", "FreeFMUState",
                                   "SerializedFMUStateSize", "SerializeFMUState",
                                   "DeserializeFMUState", "GetNumberOfVariableDependencies",
                                   "GetVariableDependencies")},
    "fmi3GetDirectionalDerivative": READABLE - {"error"},
    "fmi3GetAdjointDerivative": READABLE - {"error"},
    "fmi3EnterConfigurationMode": {"instantiated", "step mode"},
    "fmi3GetOutputDerivatives": {"step mode", "terminated", "error"},
    "fmi3DoStep": {"step mode"},
    **{f"fmi3{f}": set() for f in NEVER},
}
# What an allowed call answers: fmi3OK, but fmi3Error for what the capability flags say is
# not provided (per-element dependencies, derivatives, output derivatives, configuration).
NOT_PROVIDED = {f"fmi3{f}" for f in ("GetNumberOfVariableDependencies",
                                      "GetVariableDependencies", "GetDirectionalDerivative",
                                      "GetAdjointDerivative", "EnterConfigurationMode",
                                      "GetOutputDerivatives")}


def expected(function, state):
    return ERROR if state not in ALLOWED[function] or function in NOT_PROVIDED else OK


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmi3_fmu_passes_fmpy_validation_and_carries_linux64_only(fmi3_paths, name):
    assert validate_fmu(str(fmi3_paths[name])) == []
    assert PLATFORM == "x86_64-linux"
    assert_carries_one_platform(fmi3_paths[name], PLATFORM)


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmi3_description_has_the_fmi2_variables_with_units_and_descriptions(fmi3_paths,
                                                                             fmu_paths, name):
    new, old = (read_model_description(str(p)) for p in (fmi3_paths[name], fmu_paths[name]))
    assert new.fmiVersion == "3.0" and new.coSimulation.canGetAndSetFMUstate
    types = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
    variables = {v.name: v for v in new.modelVariables}
    assert variables.pop("time").causality == "independent"
    assert set(variables) == {v.name for v in old.modelVariables}
    for was in old.modelVariables:
        now = variables[was.name]
        assert (now.type, now.valueReference, now.causality, now.variability, now.unit,
                now.start, now.description) == (types[was.type], was.valueReference,
                                                was.causality, was.variability, was.unit,
                                                was.start, was.description)
        assert now.description
        if now.type == "Float64" and now.causality in ("input", "output"):
            assert now.unit


def max_differences(first, second, outputs):
    return {o: float(np.max(np.abs(np.asarray(first[o]) - np.asarray(second[o]))))
            for o in outputs}


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmi3_cross_check_run_equals_the_fmi2_fmus(fmi3_paths, fmu_paths, name):
    """fmpy simulates both on the FMU's cross-check input (fmus/<Name>/<Name>_in.csv)."""
    folder = FMU_SOURCES / name
    options = dict(line.split(", ")
                   for line in (folder / f"{name}_ref.opt").read_text().splitlines())
    runs = [simulate_fmu(str(path), stop_time=float(options["StopTime"]),
                         step_size=float(options["StepSize"]),
                         output_interval=float(options["StepSize"]),
                         input=read_csv(folder / f"{name}_in.csv"), output=list(OUTPUTS[name]))
            for path in (fmu_paths[name], fmi3_paths[name])]
    assert len(runs[0]) == len(runs[1]) > 10
    assert max(max_differences(*runs, OUTPUTS[name]).values()) <= 1e-12


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmi3_scripted_run_with_parameters_equals_the_fmi2_fmus(fmi3_paths, fmu_paths, name):
    """The step-by-step run of the FMI 2.0 tests (scripted inputs, changed parameters of
    every type) through fmpy's FMI 3 and FMI 2 classes."""
    runs = [run_fmu(path, STEP_SIZE_S[name], N_STEPS[name], scripted_inputs(name),
                    PARAMETERS[name], OUTPUTS[name]) for path in (fmu_paths[name],
                                                                  fmi3_paths[name])]
    assert max(max_differences(*runs, OUTPUTS[name]).values()) <= 1e-12
    assert np.ptp(runs[1][OUTPUTS[name][0]]) > 0  # the run moved


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmi3_non_finite_input_and_parameter_are_errors_naming_the_variable(fmi3_paths, name,
                                                                             capsys):
    loaded = LoadedFmu(fmi3_paths[name])
    try:
        parameter = next(v.name for v in loaded.description.modelVariables
                         if v.causality == "parameter" and v.type == "Float64")
        slave = loaded.instantiate("nonfinite")
        with pytest.raises(FMICallException):
            loaded.set_values(slave, {parameter: float("inf")})
        assert f"parameter {parameter} must be finite" in capsys.readouterr().out
        slave.reset()
        loaded.enter_initialisation(slave)
        slave.exitInitializationMode()
        state = slave.getFMUState()
        for source in [v.name for v in loaded.description.modelVariables
                       if v.causality == "input"][:1]:  # none in the circle interpolator
            with pytest.raises(FMICallException):
                loaded.set_values(slave, {source: float("nan")})
            assert (f"fmi3SetFloat64: input {source} must be finite, got nan"
                    in capsys.readouterr().out)
        slave.setFMUState(state)  # a state saved while healthy takes it out of the error state
        slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=STEP_SIZE_S[name])
        assert all(np.isfinite(loaded.get_reals(slave, OUTPUTS[name])))
        slave.freeInstance()
    finally:
        loaded.close()


@pytest.mark.parametrize("name", FMU_NAMES)
def test_every_fmi3_function_in_every_state_answers_as_the_standard_says(fmi3_paths, name,
                                                                         tmp_path):
    folder = tmp_path / f"{name} dé#"  # a path a file URI writes with %-escapes
    with zipfile.ZipFile(fmi3_paths[name]) as archive:
        archive.extractall(folder)
    run = subprocess.run([sys.executable, str(TESTS / "fmi3_probe.py"), "matrix", str(folder)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, f"the host process ended with {run.returncode}: {run.stderr[-2000:]}"
    result = json.loads(run.stdout.splitlines()[-1])
    assert set(result["answers"]) == set(ALLOWED)
    wrong = {(function, state): answer for function, row in result["answers"].items()
             for state, answer in row.items() if answer != expected(function, state)}
    assert not wrong
    assert result["alive"]
    refusals = [text for status, _, text in result["messages"] if "is not allowed in" in text]
    assert refusals and all("fmi2" not in text for _, _, text in result["messages"])


def test_fmi3_model_description_is_fmi3_schema(fmi3_paths):
    """What fmpy's schema check leaves: the structure lists each output by value reference."""
    with zipfile.ZipFile(fmi3_paths["ThermalScrew"]) as archive:
        root = ET.fromstring(archive.read("modelDescription.xml"))
    outputs = {v.get("valueReference") for v in root.find("ModelVariables")
               if v.get("causality") == "output"}
    assert {o.get("valueReference") for o in root.find("ModelStructure").iter("Output")} == outputs
    assert len(outputs) == 3


# Each tunable parameter enters only the map from the model's state to its outputs (Liu
# 2022 Eq. 1-2 for the lead error and eccentricity, Liu 2022 Eq. 9-10 for the stepper's
# harmonics, Rong et al. 2023 Eq. 1 for the ambient reference), never the state's evolution:
# set between steps k-1 and k, the run is the old value's up to step k-1 and the new value's
# from step k on.
TUNABLE = {"GeometricError": {"offset_um": 1.25, "slope_um_per_mm": 0.3,
                              "eccentricity_cos_um": -0.4, "eccentricity_sin_um": 0.7},
           "StepperError": {"harmonic1_cos_um": 0.5, "harmonic1_sin_um": -0.2,
                            "harmonic2_cos_um": 0.1, "harmonic2_sin_um": 0.05},
           "ThermalScrew": {"reference_ambient_C": 23.5}}


def run_with_change(path, name, changed_at, change):
    """run_fmu's run of ``name`` (scripted inputs, default parameters) with the parameters
    ``change`` set between steps ``changed_at - 1`` and ``changed_at`` (0: before
    initialisation); the first output per step."""
    loaded, inputs = LoadedFmu(path), scripted_inputs(name)
    h, output = STEP_SIZE_S[name], OUTPUTS[name][0]
    slave = loaded.instantiate("tunable")
    try:
        if changed_at == 0:
            loaded.set_values(slave, change)
        loaded.enter_initialisation(slave)
        slave.exitInitializationMode()
        recorded = []
        for k in range(N_STEPS[name]):
            if k == changed_at and k > 0:
                loaded.set_values(slave, change)
            loaded.set_values(slave, {n: v[k].item() for n, v in inputs.items()})
            slave.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
            recorded.append(loaded.get_reals(slave, [output])[0])
        slave.freeInstance()
    finally:
        loaded.close()
    return np.array(recorded)


@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("name", sorted(TUNABLE))
def test_a_tunable_parameter_set_mid_run_acts_from_the_next_step(fmu_paths, fmi3_paths, name,
                                                                 version):
    path = (fmu_paths if version == 2 else fmi3_paths)[name]
    variables = {v.name: v for v in read_model_description(str(path)).modelVariables}
    assert {n for n, v in variables.items() if v.variability == "tunable"} == set(TUNABLE[name])
    k = N_STEPS[name] // 2
    changed = run_with_change(path, name, k, TUNABLE[name])
    before, after = run_with_change(path, name, 0, {}), run_with_change(path, name, 0,
                                                                       TUNABLE[name])
    np.testing.assert_allclose(changed[:k], before[:k], rtol=0, atol=1e-12)
    np.testing.assert_allclose(changed[k:], after[k:], rtol=0, atol=1e-12)
    assert np.max(np.abs(after[k:] - before[k:])) > 0.01  # the change shows


def test_a_changed_lead_error_moves_the_error_by_the_published_formula(fmi3_paths):
    """Liu 2022 Eq. 1: the lead error b1 + a1·y; raising b1 by 1 µm and a1 by 0.3 µm/mm at
    step k moves every later error by 1 + 0.3·y (y = the axis position)."""
    name, k = "GeometricError", N_STEPS["GeometricError"] // 2
    change = {"offset_um": 0.2515 + 1.0, "slope_um_per_mm": -0.5084 + 0.3}
    shift = (run_with_change(fmi3_paths[name], name, k, change)
             - run_with_change(fmi3_paths[name], name, 0, {}))
    position = scripted_inputs(name)["position_mm"]
    np.testing.assert_allclose(shift[k:], 1.0 + 0.3 * position[k:], rtol=0, atol=1e-12)
    assert np.all(shift[:k] == 0.0)


@pytest.mark.parametrize("version", (2, 3))
def test_a_fixed_parameter_is_still_refused_mid_run(fmu_paths, fmi3_paths, capsys, version):
    path = (fmu_paths if version == 2 else fmi3_paths)["ThermalScrew"]
    loaded = LoadedFmu(path)
    try:
        slave = loaded.instantiate("fixed")
        loaded.enter_initialisation(slave)
        slave.exitInitializationMode()
        with pytest.raises(FMICallException):
            loaded.set_values(slave, {"conductivity_W_mK": 500.0})
        assert "conductivity_W_mK is a fixed parameter" in capsys.readouterr().out
        slave.freeInstance()
    finally:
        loaded.close()


def test_the_master_runs_the_fmi3_fmus_as_the_fmi2_ones(fmu_paths, fmi3_paths):
    """The project's master (feedaxis.cosim) over the default axis: the four FMI 3.0 FMUs
    give every signal of the FMI 2.0 ones, bit for bit."""
    from feedaxis.cosim.master import Master
    from feedaxis.cosim.system import default_axis

    t = np.arange(1500) * 1e-3
    inputs = {"position_ref_mm": 40.0 * np.sin(2 * np.pi * 0.5 * t),
              "disturbance_N": 50.0 * np.sin(2 * np.pi * 30.0 * t) * (t > 1.0),
              "ambient_C": 20.0 + 0.5 * t}
    results = []
    for paths in (fmu_paths, fmi3_paths):
        with Master(default_axis(), paths) as master:
            results.append(master.run(1.5, inputs))
    assert results[0].dtype.names == results[1].dtype.names
    for name in results[0].dtype.names:
        assert np.array_equal(results[0][name], results[1][name]), name
    assert np.ptp(results[1]["positioning_error_um"]) > 0.1


def omsimulator_run(ssp, folder):
    """The OMSimulator program's run of ``ssp`` to 0.2 s: {column name: values}."""
    from conftest import FMI_TOOLS, require_tool

    program = FMI_TOOLS / "omsimulator" / "bin" / "OMSimulator"
    require_tool(program)
    run = subprocess.run([str(program), "--stopTime=0.2", "--resultFile=result.csv", str(ssp)],
                         cwd=folder, capture_output=True, text=True, timeout=300)
    errors = [line for line in (run.stdout + run.stderr).splitlines() if line.startswith("error")]
    assert run.returncode == 0 and not errors, (run.stdout + run.stderr)[-3000:]
    lines = (folder / "result.csv").read_text().splitlines()
    names = [name.strip().strip('"') for name in lines[0].split(",")]
    table = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
    return {name: table[:, i] for i, name in enumerate(names)}


def test_the_fmi3_ssp_runs_in_the_omsimulator_program_as_the_fmi2_one(fmu_paths, fmi3_paths,
                                                                     tmp_path):
    """export-ssp --fmi 3: SSP 1.0 with the FMI 3.0 FMUs, in OMSimulator's program (a C
    host); every column the FMI 2.0 SSP's run has, equal."""
    from feedaxis.cosim.ssp import export_ssp
    from feedaxis.cosim.system import default_axis

    system = default_axis().with_steps(ThermalScrew=1e-3)
    runs = []
    for version, paths in ((2, fmu_paths), (3, fmi3_paths)):
        folder = tmp_path / f"fmi{version}"
        folder.mkdir()
        runs.append(omsimulator_run(export_ssp(folder / "axis.ssp", system, paths), folder))
    assert set(runs[0]) <= set(runs[1])
    for name, values in runs[0].items():
        assert np.array_equal(values, runs[1][name]), name
    geometric = next(n for n in runs[1] if n.endswith("GeometricError.error_um"))
    assert runs[1][geometric][-1] == pytest.approx(0.45106988665543396, rel=1e-12)


def fmi3_instantiate_cases(folder, token):
    """(name, instantiation token, resource path, instantiable) for the FMI 3.0 FMU of
    ``token`` unpacked in ``folder`` (as its host sees the path): the absolute path FMI 3.0
    passes, with its final '/' or without, and what a resource path is not."""
    path = f"{folder}/resources/"
    return [("probe", token, path, True), ("probe", token, path.rstrip("/"), True),
            ("probe", token, f"{folder}/missing/", False), ("probe", token, "resources/", False),
            ("probe", token, (Path(folder) / "resources").as_uri(), False),
            ("probe", token, "<NULL>", False), ("<NULL>", token, path, False),
            ("", token, path, False),
            ("probe", "{00000000-0000-0000-0000-000000000000}", path, False),
            ("probe", "<NULL>", path, False)]


def test_fmi3_instantiate_answers_every_argument_in_a_c_host(fmi3_paths, tmp_path):
    """The FMI 3.0 C host of the tests, one process per case: an instance that steps, or
    NULL and one error of fmi3InstantiateCoSimulation saying why; never a signal."""
    folder = tmp_path / "servo dé#"
    with zipfile.ZipFile(fmi3_paths["NpidServo"]) as archive:
        archive.extractall(folder)
    program = compile_c_host(tmp_path / "fmi3_c_host", fmi=3)
    token = read_model_description(str(folder)).guid
    for case in fmi3_instantiate_cases(folder, token):
        check_instantiate_answer(case, *c_host_instantiate([str(program)], case, folder,
                                                           "NpidServo"),
                                 function="fmi3InstantiateCoSimulation")
