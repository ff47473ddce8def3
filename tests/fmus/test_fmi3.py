"""The FMI 3.0 co-simulation FMUs (``build-fmus --fmi 3``): valid, carrying linux64 only,
the FMI 2.0 FMUs' results to 1e-12 from the same slave and physics, and the FMI 3.0 state
machine as a host sees it through fmpy's low-level FMI 3 API (tests/fmi3_probe.py, one
process per FMU)."""
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
from feedaxis.fmu_build import FMU_NAMES, build_fmus
from feedaxis.fmu_fmi3 import PLATFORM
from scenarios import N_STEPS, OUTPUTS, PARAMETERS, STEP_SIZE_S, scripted_inputs

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


@pytest.fixture(scope="module")
def fmi3_paths(tmp_path_factory):
    """Name -> path of each FMI 3.0 FMU, freshly built."""
    return {path.stem: path for path in build_fmus(tmp_path_factory.mktemp("fmi3"), fmi=3)}


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmi3_fmu_passes_fmpy_validation_and_carries_linux64_only(fmi3_paths, name):
    assert validate_fmu(str(fmi3_paths[name])) == []
    with zipfile.ZipFile(fmi3_paths[name]) as archive:
        binaries = {n.split("/")[1] for n in archive.namelist() if n.startswith("binaries/")}
    assert binaries == {PLATFORM} == {"x86_64-linux"}


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
        source = next(v.name for v in loaded.description.modelVariables
                      if v.causality == "input")
        with pytest.raises(FMICallException):
            loaded.set_values(slave, {source: float("nan")})
        assert f"fmi3SetFloat64: input {source} must be finite, got nan" in capsys.readouterr().out
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
