"""The FMI 2.0 contract of the four FMUs as a host sees it (issue 34): fmi2Instantiate's
arguments, the standard's state machine, values checked where they are set, recovery by a
saved state. Hosts: fmpy's low-level API and the C host of the tests (tests/fmi_c_host.c),
each call that could end a process in a process of its own (tests/fmi2_probe.py).
"""
import json
import math
import shutil
import subprocess
import sys
import zipfile
from ctypes import byref, c_char_p, c_uint
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from feedaxis.fmu_build import FMU_NAMES
from scenarios import OUTPUTS, STEP_SIZE_S
from test_fmus import initialised

TESTS = Path(__file__).resolve().parents[1]
PROBE = TESTS / "fmi2_probe.py"
HEADERS = TESTS.parent / "fmus" / "common"
OK, DISCARD, ERROR = 0, 2, 3
STATES = ("instantiated", "initialisation", "step complete", "terminated", "error")

# The FMI 2.0 standard's table of the co-simulation functions callable per state (section
# 4.2.4), written out here from the standard, apart from the layer's own table (states.c).
EVERY = set(STATES)
INITIALISED = {"initialisation", "step complete", "terminated", "error"}
SETTABLE = {"instantiated", "initialisation", "step complete"}
STATUS = {"step complete", "terminated"}  # and stepFailed, stepInProgress: never entered
ALLOWED = {
    "fmi2SetDebugLogging": EVERY, "fmi2SetupExperiment": {"instantiated"},
    "fmi2EnterInitializationMode": {"instantiated"},
    "fmi2ExitInitializationMode": {"initialisation"}, "fmi2Terminate": {"step complete"},
    "fmi2Reset": EVERY,
    **{f"fmi2Get{t}": INITIALISED for t in ("Real", "Integer", "Boolean", "String")},
    **{f"fmi2Set{t}": SETTABLE for t in ("Real", "Integer", "Boolean", "String")},
    **{f: EVERY for f in ("fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate",
                          "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate",
                          "fmi2DeSerializeFMUstate")},
    "fmi2GetDirectionalDerivative": INITIALISED, "fmi2SetRealInputDerivatives": SETTABLE,
    "fmi2GetRealOutputDerivatives": {"step complete", "terminated", "error"},
    "fmi2DoStep": {"step complete"}, "fmi2CancelStep": set(),  # stepInProgress only
    **{f"fmi2Get{t}Status": STATUS for t in ("", "Real", "Integer", "Boolean", "String")},
}
# What an allowed call answers: fmi2OK, but fmi2Error for what the capability flags say is
# not provided, and fmi2Discard for a status kind the FMU does not provide (the standard).
NOT_PROVIDED = {"fmi2GetDirectionalDerivative": ERROR, "fmi2SetRealInputDerivatives": ERROR,
                "fmi2GetRealOutputDerivatives": ERROR, "fmi2GetStatus": DISCARD,
                "fmi2GetIntegerStatus": DISCARD, "fmi2GetStringStatus": DISCARD}


def expected(function, state):
    return NOT_PROVIDED.get(function, OK) if state in ALLOWED[function] else ERROR


@pytest.fixture(scope="module")
def unpacked(fmu_paths, tmp_path_factory):
    """Name -> folder of each FMU unpacked under a name with a space and a non-ASCII letter,
    which file URIs write as %-escapes."""
    folders = {}
    for name, path in fmu_paths.items():
        folder = tmp_path_factory.mktemp("unpacked") / f"{name} dé#"
        with zipfile.ZipFile(path) as archive:
            archive.extractall(folder)
        folders[name] = folder
    return folders


def probe(*arguments):
    run = subprocess.run([sys.executable, str(PROBE), *map(str, arguments)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, f"the host process ended with {run.returncode}: {run.stderr[-2000:]}"
    return json.loads(run.stdout.splitlines()[-1])


@pytest.mark.parametrize("name", FMU_NAMES)
def test_every_fmi2_function_in_every_state_answers_as_the_standard_says(unpacked, name):
    answers = probe("matrix", unpacked[name])["answers"]
    assert set(answers) == set(ALLOWED)
    wrong = {(function, state): answer for function, row in answers.items()
             for state, answer in row.items() if answer != expected(function, state)}
    assert not wrong


def guid_of(folder):
    return read_model_description(str(folder)).guid


def resource_cases(folder):
    """(resource location, instantiable) for every form a host may pass, and some it may not."""
    path = f"{folder}/resources"
    uri = (Path(folder) / "resources").as_uri()  # %-escapes for the space, é and #
    assert "%20" in uri and "%C3%A9" in uri and "%23" in uri
    return [
        (uri, True), (uri.replace("file:///", "file:/"), True),
        (uri.replace("file:///", "file://localhost/"), True),
        (uri.replace("file:///", "FILE://LocalHost/"), True),
        (uri.replace("resources", "%72esources"), True), (uri + "/", True),
        (uri.replace("/resources", "/missing"), False),
        (uri.replace("file:///", "file://elsewhere/"), False),
        (uri.replace("%20", "%2"), False), (uri.replace("%20", "%zz"), False),
        (uri.replace("%20", "%00"), False), (uri + "?query", False), (path, False),
        (f"http://localhost{path}", False), ("<NULL>", False),
    ]


def instantiate_cases(folder, guid):
    """(name, guid, resources, instantiable) for the FMU of ``guid`` unpacked in ``folder``
    (as its host sees the path)."""
    uri = (Path(folder) / "resources").as_uri()
    return ([("probe", guid, resources, ok) for resources, ok in resource_cases(folder)]
            + [("<NULL>", guid, uri, False), ("", guid, uri, False),
               ("probe", "{00000000-0000-0000-0000-000000000000}", uri, False),
               ("probe", "<NULL>", uri, False)])


def check_instantiate_answer(case, instance, stepped, messages, function="fmi2Instantiate"):
    """Instantiable: an instance that steps, no error; else NULL and one error of
    ``function`` naming why."""
    *_, instantiable = case
    assert instance == instantiable, (case, messages)
    assert stepped == instantiable, (case, messages)
    errors = [text for status, _, text in messages if status >= ERROR]
    if instantiable:
        assert not errors, (case, errors)
    else:
        assert len(errors) == 1 and f"{function}: " in errors[0], (case, messages)


def test_fmi2_instantiate_answers_every_argument_in_fmpy(unpacked):
    """One process per case, through fmpy's low-level API (fmi2Instantiate called directly)."""
    folder = unpacked["StepperError"]
    for case in instantiate_cases(folder, guid_of(folder)):
        result = probe("instantiate", folder, *case[:3])
        check_instantiate_answer(case, result["instance"], result["stepped"],
                                 result["messages"])


def compile_c_host(program, fmi=2):
    """The C host of the tests (tests/fmi_c_host.c, a host with no Python in the process)
    making its calls in FMI version ``fmi`` (tests/fmi2_c_host.c, tests/fmi3_c_host.c),
    compiled into ``program``."""
    if not shutil.which("cc"):
        pytest.skip("no C compiler")
    subprocess.run(["cc", "-O2", f"-I{HEADERS / f'fmi{fmi}'}", "-o", str(program),
                    str(TESTS / "fmi_c_host.c"), str(TESTS / f"fmi{fmi}_c_host.c"), "-ldl"],
                   check=True)
    return program


@pytest.fixture(scope="module")
def c_host(tmp_path_factory):
    """The FMI 2.0 C host of the tests (:func:`compile_c_host`)."""
    return compile_c_host(tmp_path_factory.mktemp("host") / "fmi_c_host")


def c_host_instantiate(command, case, folder, identifier):
    """Run the C host's instantiate mode for ``case``: (instance, stepped, messages)."""
    run = subprocess.run([*command, "instantiate", str(folder), identifier, *case[:3]],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, f"the C host ended with {run.returncode}: {run.stdout[-2000:]}"
    lines = run.stdout.splitlines()
    value = {line.split()[0]: line.split()[1] for line in lines
             if line.split()[0] in ("instance", "stepped")}
    messages = [[int(line.split(" ", 3)[1]), line.split(" ", 3)[2], line.split(" ", 3)[3]]
                for line in lines if line.startswith("log ")]
    return value["instance"] == "1", value["stepped"] == "1", messages


def test_fmi2_instantiate_answers_every_argument_in_a_c_host(unpacked, c_host):
    folder = unpacked["NpidServo"]
    for case in instantiate_cases(folder, guid_of(folder)):
        check_instantiate_answer(case, *c_host_instantiate([str(c_host)], case, folder,
                                                           "NpidServo"))


def vr(loaded, name):
    return loaded.variables[name].valueReference


def test_a_state_saved_while_healthy_takes_the_instance_out_of_the_error_state(loaded_fmus,
                                                                                capsys):
    """A step the slave refuses (a communication step of 0) is fmi2Error; fmi2DoStep is then
    refused; fmi2SetFMUstate with the state saved before the error, and the run goes on
    exactly as one that never failed."""
    loaded = loaded_fmus["ThermalScrew"]
    h, outputs = STEP_SIZE_S["ThermalScrew"], OUTPUTS["ThermalScrew"]
    runs = []
    for fail in (False, True):
        slave = initialised(loaded)
        slave.setReal([vr(loaded, "velocity_mm_s")], [250.0])
        slave.doStep(0.0, h)
        healthy = slave.getFMUstate()
        if fail:
            with pytest.raises(FMICallException) as failure:
                slave.doStep(h, 0.0)
            assert failure.value.status == ERROR
            with pytest.raises(FMICallException):
                slave.doStep(h, h)
            slave.setFMUstate(healthy)
        slave.doStep(h, h)
        runs.append(loaded.get_reals(slave, outputs))
        slave.freeFMUstate(healthy)
        slave.terminate()
        slave.freeInstance()
    assert runs[0] == runs[1] and np.isfinite(runs[0]).all()
    out = capsys.readouterr().out
    assert "communication step size must be finite and > 0" in out
    assert "fmi2DoStep is not allowed in the error state" in out


@pytest.mark.parametrize("value, reason", [(b"fixed-\xff", "is not UTF-8 (byte 6)"),
                                           (b"\xc0\xaf", "is not UTF-8 (byte 0)"),
                                           (None, "NULL string for support")])
def test_a_string_that_is_null_or_not_utf8_is_an_error_naming_it(loaded_fmus, capsys, value,
                                                                   reason):
    loaded = loaded_fmus["GeometricError"]
    slave = loaded.instantiate("strings")
    try:
        status = slave.dll.fmi2SetString(slave.component, (c_uint * 1)(vr(loaded, "support")),
                                         1, (c_char_p * 1)(value))
        assert status == ERROR
        assert f"fmi2SetString: {'the value for support ' if value else ''}{reason}" \
            in capsys.readouterr().out
        slave.reset()
        slave.setString([vr(loaded, "support")], ["fixed-fixed"])
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        assert slave.getString([vr(loaded, "support")]) == [b"fixed-fixed"]
    finally:
        slave.freeInstance()


def real_variables(loaded):
    """Names of the Real parameters and inputs a host may set before initialisation."""
    return sorted(name for name, v in loaded.variables.items()
                  if v.type == "Real" and v.causality in ("parameter", "input"))


ANY_FLOAT = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                      st.sampled_from([1e308, -1e308, 1e300, 5e-324, 0.0, -0.0]))


def outcome(loaded, values, n_steps=3):
    """Set ``values`` (name -> value), initialise and step: the outputs after each step
    (all OK), or None where a call was refused with fmi2Error."""
    slave = loaded.instantiate("property")
    try:
        loaded.set_values(slave, values)
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        outputs = [v.valueReference for v in loaded.variables.values()
                   if v.causality == "output"]
        seen = [slave.getReal(outputs)]
        for k in range(n_steps):
            slave.doStep(k * 0.01, 0.01)
            seen.append(slave.getReal(outputs))
        return seen
    except FMICallException as failure:
        assert failure.status == ERROR, failure
        return None
    finally:
        slave.freeInstance()


@pytest.mark.parametrize("name", FMU_NAMES)
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_no_output_is_ever_non_finite_with_fmi2ok(loaded_fmus, capsys, name, data):
    """Any Real parameter or input set to any float (NaN, ±inf, ±1e308, the extremes): either
    a call says fmi2Error naming a variable, or every output of every step is finite."""
    loaded = loaded_fmus[name]
    names = data.draw(st.lists(st.sampled_from(real_variables(loaded)), min_size=1,
                               max_size=3, unique=True))
    values = {n: data.draw(ANY_FLOAT, label=n) for n in names}
    seen = outcome(loaded, values)
    out = capsys.readouterr().out
    if seen is None:
        errors = [line for line in out.splitlines() if "[ERROR]" in line]
        assert errors and any(v in errors[-1] for v in [*loaded.variables, "time_step_s"]), out
    else:
        assert all(math.isfinite(x) for row in seen for x in row), (values, seen)


@pytest.mark.parametrize("name, values, named", [
    ("ThermalScrew", {"expansion_per_K": 1e308}, "initialisation: output error_um = "),
    ("ThermalScrew", {"reference_ambient_C": math.nan}, "reference_ambient_C must be finite"),
    ("GeometricError", {"backlash_um": math.inf}, "backlash_um must be finite"),
    ("StepperError", {"harmonic2_sin_um": -math.inf}, "harmonic2_sin_um must be finite"),
    ("NpidServo", {"position_ref_mm": 1e308}, "(the inputs: position_ref_mm = 1e+308,"),
    ("NpidServo", {"position_ref_mm": -1e308}, "(the inputs: position_ref_mm = -1e+308,"),
])
def test_values_the_issue_found_reported_as_ok_are_errors_naming_them(loaded_fmus, capsys,
                                                                      name, values, named):
    """The cases that gave non-finite outputs with fmi2OK (issue 34): now fmi2Error."""
    assert outcome(loaded_fmus[name], values) is None
    errors = [line for line in capsys.readouterr().out.splitlines() if "[ERROR]" in line]
    assert len(errors) == 1 and named in errors[0], errors
