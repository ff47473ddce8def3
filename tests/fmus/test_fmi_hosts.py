"""The FMUs in hosts that are not Python processes, and never crashing any host.

fmuCheck (FMI Compliance Checker, a plain C program) loads each FMU, simulates its
cross-check input and must match the cross-check reference; a bad parameter, a fixed
parameter set late, calls after a failure, tiny and huge steps all end in a status and a
message with a category, never a crash. Tests needing a tool of ``FEEDAXIS_FMI_TOOLS``
(docs/fmu-hosts.md) skip with the reason outside CI and fail in CI (CI=true).
"""
import os
import re
import subprocess
import sys
import time
import zipfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.util import read_csv

from conftest import FMI_TOOLS, require_system_library, require_tool, unavailable
from feedaxis.fmu_build import FMU_NAMES
from feedaxis.physics import thermal

ROOT = Path(__file__).resolve().parents[2]
FMU_SOURCES = ROOT / "fmus"
FMU_CHECK = FMI_TOOLS / "fmuCheck.linux64"
ERROR = 3
ECOS_LIBRARY = "libtbb.so.12"   # ecospy's binaries (ecos, libecosc.so) link it


def require_ecospy():
    """ecospy's folder; skip (fail in CI) when ecospy or the libtbb its binaries need is
    missing."""
    import importlib.util
    require_system_library(ECOS_LIBRARY)
    spec = importlib.util.find_spec("ecospy")
    if spec is None:
        unavailable("ecospy is not installed (pip install '.[test]' brings it)")
    return Path(spec.origin).parent


def cross_check_options(name):
    text = (FMU_SOURCES / name / f"{name}_ref.opt").read_text()
    return {key: float(value) for key, value in (line.split(", ") for line in text.splitlines())}


def cross_check_command(name, input_csv, result_csv, fmu_path, program=FMU_CHECK, extra=()):
    """fmuCheck's command line for ``name``'s cross-check run (the _ref.opt options);
    ``extra``: more fmuCheck options. An FMU without inputs (its _in.csv holds the time
    column only, which fmuCheck refuses: "Cannot find input variable '0'") runs without -i."""
    options = cross_check_options(name)
    header = (FMU_SOURCES / name / f"{name}_in.csv").read_text().splitlines()[0]
    inputs = ["-i", str(input_csv)] if "," in header else []
    return [str(program), "-k", "cs", "-s", repr(options["StopTime"]), "-h",
            repr(options["StepSize"]), "-l", "3", *inputs, "-o", str(result_csv),
            *extra, str(fmu_path)]


def assert_cross_check_passed(name, run, result_csv):
    """fmuCheck exited 0 without errors and ``result_csv`` matches ``<name>_ref.csv``."""
    report = run.stdout + run.stderr
    assert run.returncode == 0, report[-2000:]
    assert "[FATAL]" not in report and "[ERROR]" not in report, report[-2000:]
    assert "0 Error(s)" in report and "0 Warning(s)" in report
    options = cross_check_options(name)
    result, reference = read_csv(result_csv), read_csv(FMU_SOURCES / name / f"{name}_ref.csv")
    steps = result["time"] / options["StepSize"]
    on_step = np.abs(steps - np.rint(steps)) < 1e-6
    assert on_step.sum() >= 100
    rows = np.rint(steps[on_step]).astype(int)
    for output in reference.dtype.names[1:]:
        expected = reference[output][rows]
        np.testing.assert_allclose(result[output][on_step], expected, rtol=1e-9,
                                   atol=1e-9 * np.max(np.abs(reference[output])))


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmu_check_simulates_cross_check_input_in_a_c_host(fmu_paths, tmp_path, name):
    require_tool(FMU_CHECK)
    result_csv = tmp_path / "out.csv"
    run = subprocess.run(cross_check_command(name, FMU_SOURCES / name / f"{name}_in.csv",
                                             result_csv, fmu_paths[name]),
                         capture_output=True, text=True, timeout=300)
    assert_cross_check_passed(name, run, result_csv)


def instantiate_in_fmu_check(fmu_path, **environment):
    """fmuCheck's report on ``fmu_path`` with ``environment`` added; it must not be
    instantiable: exit 1 (fmuCheck's "could not instantiate", not a signal), a fatal message."""
    run = subprocess.run([str(FMU_CHECK), "-k", "cs", "-l", "3", str(fmu_path)],
                         capture_output=True, text=True, timeout=60,
                         env=dict(os.environ, **environment))
    report = run.stdout + run.stderr
    assert run.returncode == 1 and "[logStatusFatal]" in report, report[-2000:]
    return report


def test_c_host_without_python_gets_a_message_naming_the_variable(fmu_paths):
    require_tool(FMU_CHECK)
    report = instantiate_in_fmu_check(fmu_paths["StepperError"],
                                      FEEDAXIS_LIBPYTHON="/nonexistent/libpython3.so")
    assert "cannot load FEEDAXIS_LIBPYTHON=/nonexistent/libpython3.so: " in report


def test_a_wrong_feedaxis_python_fails_instantiate_naming_it(fmu_paths):
    """It used to be ignored: Python started from the libpython's own prefix instead."""
    require_tool(FMU_CHECK)
    report = instantiate_in_fmu_check(fmu_paths["StepperError"],
                                      FEEDAXIS_PYTHON="/nonexistent/python")
    assert "cannot use FEEDAXIS_PYTHON=/nonexistent/python as the Python: No such file" in report


def test_a_libpython_of_another_minor_version_is_refused(fmu_paths, tmp_path):
    """The host layer is compiled against the building Python's C API: a libpython of
    another minor version (here a stand-in exporting what the layer asks first) is refused
    before anything of it runs."""
    require_tool(FMU_CHECK)
    source = tmp_path / "fake.c"
    source.write_text('const char *Py_GetVersion(void) { return "3.10.14 (stand-in)"; }\n'
                      "int Py_IsInitialized(void) { return 0; }\n")
    library = tmp_path / "libpython3.10.so"
    subprocess.run(["cc", "-shared", "-fPIC", "-o", str(library), str(source)], check=True)
    report = instantiate_in_fmu_check(fmu_paths["StepperError"], FEEDAXIS_LIBPYTHON=str(library))
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    assert (f"FEEDAXIS_LIBPYTHON={library} is Python 3.10.14; this FMU needs CPython {version}"
            in report)


def test_the_host_layer_is_checked_against_the_fmi_headers(tmp_path):
    """The official fmi2Functions.h declares every export: a definition that strays from the
    standard's signature does not compile."""
    import sysconfig
    exports = FMU_SOURCES / "common" / "host" / "exports.c"
    source = exports.read_text()
    definition = source.index("EXPORT fmi2Status fmi2GetReal(")
    signature_end = source.index("{", definition)
    signature = source[definition:signature_end]
    assert "fmi2Real value[]" in signature
    (tmp_path / "wrong.c").write_text(source[:definition] + signature.replace(
        "fmi2Real value[]", "float value[]") + source[signature_end:])
    (tmp_path / "feedaxis_fmi_vars.h").write_text(
        "typedef struct { unsigned vr; char kind; char type; const char *name; double min, max; }"
        " FeedaxisVar;\n"
        "static const FeedaxisVar FEEDAXIS_VARS[] = {{0, 'u', 'R', \"x\", -HUGE_VAL, HUGE_VAL}};\n"
        "#define FEEDAXIS_N_VARS 1\n")
    run = subprocess.run(["cc", "-fsyntax-only", f"-I{sysconfig.get_paths()['include']}",
                          f"-I{FMU_SOURCES / 'common' / 'fmi2'}", f"-I{exports.parent}",
                          f"-I{tmp_path}", '-DFEEDAXIS_PYTHON_VERSION="3"',
                          '-DFEEDAXIS_PYTHON="p"', '-DFEEDAXIS_LIBPYTHON="l"',
                          '-DFEEDAXIS_GUID="g"', str(tmp_path / "wrong.c")],
                         capture_output=True, text=True)
    assert run.returncode != 0
    assert re.search(r"conflicting types for .fmi2GetReal.", run.stderr), run.stderr


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmu_check_accepts_model_description(fmu_paths, name):
    require_tool(FMU_CHECK)
    run = subprocess.run([str(FMU_CHECK), "-k", "xml", str(fmu_paths[name])],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0 and "0 Warning(s)" in run.stdout + run.stderr


@pytest.mark.parametrize("name", FMU_NAMES)
def test_model_description_for_strict_importers(fmu_paths, name):
    with zipfile.ZipFile(fmu_paths[name]) as archive:
        root = ET.fromstring(archive.read("modelDescription.xml"))
    options = cross_check_options(name)
    experiment = root.find("DefaultExperiment")
    assert float(experiment.get("stopTime")) == options["StopTime"]
    assert float(experiment.get("stepSize")) == options["StepSize"]
    variables = list(root.iter("ScalarVariable"))
    outputs = [i for i, v in enumerate(variables, 1) if v.get("causality") == "output"]
    for index in outputs:
        assert variables[index - 1].get("initial") == "calculated"
        assert variables[index - 1][0].get("start") is None
    structure = root.find("ModelStructure")
    assert [int(u.get("index")) for u in structure.find("Outputs")] == outputs
    assert all(u.get("dependencies") == "" for u in structure.find("Outputs"))
    assert [int(u.get("index")) for u in structure.find("InitialUnknowns")] == outputs
    declared = {u.get("name") for u in root.iter("Unit")}
    used = {v[0].get("unit") for v in variables if v[0].get("unit")}
    assert used <= declared


class Messages:
    """An fmi2 logger recording (status, category, message) for a low-level fmpy slave."""

    def __init__(self):
        self.records = []
        self.callback = fmi2CallbackLoggerTYPE(self._log)

    def _log(self, environment, instance, status, category, message):
        self.records.append((status, category, message))

    def callbacks(self):
        functions = fmi2CallbackFunctions()
        functions.logger = self.callback
        return functions


def fresh(loaded):
    """The FMU's slave object with no instance yet (LoadedFmu keeps one per FMU)."""
    from fmpy.fmi2 import FMU2Slave
    return FMU2Slave(guid=loaded.description.guid, unzipDirectory=loaded.unzip_dir,
                     modelIdentifier=loaded.description.coSimulation.modelIdentifier,
                     instanceName="guarded")


def vr(loaded, name):
    return loaded.variables[name].valueReference


def test_bad_parameter_is_an_error_with_category_and_the_instance_stays_safe(loaded_fmus):
    """A parameter below its declared min is refused where it is set; one within it that the
    physics cannot take, at fmi2ExitInitializationMode; both name it (logStatusError) and
    leave the instance in the error state, which fmi2DoStep cannot use and fmi2Reset leaves."""
    loaded, messages = loaded_fmus["GeometricError"], Messages()
    slave = fresh(loaded)
    slave.instantiate(callbacks=messages.callbacks())
    with pytest.raises(FMICallException) as below:
        slave.setReal([vr(loaded, "diameter_m")], [-1.0])
    assert below.value.status == ERROR
    assert b"parameter diameter_m = -1 is below its min 0" in messages.records[-1][2]
    slave.reset()
    slave.setReal([vr(loaded, "diameter_m")], [0.0])
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    with pytest.raises(FMICallException) as failure:
        slave.exitInitializationMode()
    assert failure.value.status == ERROR
    status, category, message = messages.records[-1]
    assert status == ERROR and category == b"logStatusError" and b"diameter_m" in message
    with pytest.raises(FMICallException) as again:
        slave.doStep(0.0, 0.01)
    assert again.value.status == ERROR
    assert messages.records[-1][1] == b"logStatusError"
    assert b"fmi2DoStep is not allowed in the error state" in messages.records[-1][2]
    slave.reset()
    slave.freeInstance()
    slave.freeLibrary()


def test_fixed_parameter_set_after_initialisation_is_refused(loaded_fmus):
    """Refused by name; the instance is then in the error state, and a state saved before
    takes it back to where it was."""
    loaded, messages = loaded_fmus["StepperError"], Messages()
    slave = fresh(loaded)
    slave.instantiate(callbacks=messages.callbacks())
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    slave.setReal([vr(loaded, "position_mm")], [0.37])
    slave.doStep(0.0, 0.01)
    before = slave.getReal([vr(loaded, "error_um")])
    healthy = slave.getFMUstate()
    with pytest.raises(FMICallException) as failure:
        slave.setReal([vr(loaded, "lead_mm")], [0.5])
    assert failure.value.status == ERROR
    assert b"lead_mm is a fixed parameter" in messages.records[-1][2]
    slave.setFMUstate(healthy)
    slave.doStep(0.01, 0.01)
    assert slave.getReal([vr(loaded, "error_um")]) == before
    slave.terminate()
    slave.freeInstance()
    slave.freeLibrary()


def run_one_step(loaded, parameters, step_s, messages):
    slave = fresh(loaded)
    slave.instantiate(callbacks=messages.callbacks())
    loaded.set_values(slave, parameters)
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    try:
        slave.exitInitializationMode()
        slave.doStep(0.0, step_s)
        outputs = slave.getReal([loaded.variables[n].valueReference for n in loaded.variables
                                 if loaded.variables[n].causality == "output"])
        slave.terminate()
        return outputs
    finally:
        slave.freeInstance()
        slave.freeLibrary()


def test_thermal_screw_takes_a_tiny_and_a_huge_step(loaded_fmus):
    loaded = loaded_fmus["ThermalScrew"]
    assert np.isfinite(run_one_step(loaded, {"velocity_mm_s": 100.0}, 1e-13, Messages())).all()
    start = time.perf_counter()
    outputs = run_one_step(loaded, {"velocity_mm_s": 100.0}, 1e6, Messages())
    assert time.perf_counter() - start < 5.0  # 1e7 sub-steps one by one would take minutes
    assert np.isfinite(outputs).all()


def test_euler_by_powers_equals_the_loop():
    params = thermal.ThermalScrewParams()
    rates = thermal.rate_matrix(params, 6000.0, thermal.nut_cells(params.cells, 0.3))
    sources = thermal.source_rate(params.cells, 6000.0, thermal.nut_cells(params.cells, 0.3))
    rise_K = np.linspace(0.0, 2.0, params.n_cells)
    looped = rise_K.copy()
    for _ in range(500):
        looped = looped + 0.05 * (rates @ looped + sources)
    powered = thermal._euler_steps_by_powers(rates, sources, rise_K, 0.05, 500)
    np.testing.assert_allclose(powered, looped, rtol=1e-10, atol=1e-12)


def test_servo_refuses_unbounded_steps_with_a_message(loaded_fmus):
    loaded, messages = loaded_fmus["NpidServo"], Messages()
    with pytest.raises(FMICallException) as failure:
        run_one_step(loaded, {}, 1000.0, messages)
    assert failure.value.status == ERROR
    assert b"internal steps" in messages.records[-1][2]
    with pytest.raises(FMICallException):
        run_one_step(loaded, {"time_step_s": 1e300}, 1e-3, messages)
    assert b"time_step_s = 1e+300 is above its max 0.001" in messages.records[-1][2]


HOST_SCRIPT = """
import sys
from fmpy import simulate_fmu
for path in sys.argv[1:]:
    simulate_fmu(path, stop_time=0.05, step_size=0.01)
print("done")
"""


def test_no_exit_time_abort_with_all_fmus_in_one_process(fmu_paths):
    """The full count (200 processes) is benchmarks/stress_fmu_hosts.py; here 10."""
    paths = [str(fmu_paths[name]) for name in FMU_NAMES]
    for _ in range(10):
        run = subprocess.run([sys.executable, "-c", HOST_SCRIPT, *paths], capture_output=True,
                             text=True, timeout=120)
        assert run.returncode == 0 and "done" in run.stdout, run.stderr[-2000:]


def test_instantiate_free_cycles_do_not_grow_python_objects(loaded_fmus):
    import gc
    loaded = loaded_fmus["StepperError"]
    for _ in range(20):
        loaded.instantiate("cycle").freeInstance()
    gc.collect()
    objects, path_length = len(gc.get_objects()), len(sys.path)
    for _ in range(300):
        loaded.instantiate("cycle").freeInstance()
    gc.collect()
    # pythonfmu's findClass leaks the MRO list of the slave class per fmi2Instantiate; fmpy
    # unloads the FMU's library at every free, and with it the pool of instances the host
    # layer would reuse through fmi2Reset (fmus/README.md): one list per cycle, pythonfmu's
    assert len(gc.get_objects()) - objects <= 300 + 10
    assert len(sys.path) == path_length


def mapped_files(name):
    """Paths of the mapped files named ``name`` in this process (deleted ones included)."""
    return {line.split(None, 5)[5] for line in Path("/proc/self/maps").read_text().splitlines()
            if len(line.split(None, 5)) == 6 and f"/{name}" in line.split(None, 5)[5]}


def test_loading_from_fresh_folders_again_and_again_keeps_nothing(fmu_paths, tmp_path):
    """Issue 26: each load from a freshly unpacked folder kept the FMU's two libraries mapped
    (0.35 MB a cycle, 74-102 MB over 200 in fmpy) and one more sys.path entry; unloading the
    FMU now frees its pooled instances and unloads pythonfmu's library."""
    import gc

    from feedaxis.cosim.fmu_runner import run_fmu

    def cycle():  # unpack, instantiate, initialise, step, free, delete the folder
        run_fmu(fmu_paths["NpidServo"], 1e-3, 1)

    cycle()
    gc.collect()
    libraries = mapped_files("libpythonfmu-export.so") | mapped_files("NpidServo.so")
    objects, path_length = len(gc.get_objects()), len(sys.path)
    resident_kB = int(Path("/proc/self/statm").read_text().split()[1]) * 4
    for _ in range(40):
        cycle()
    gc.collect()
    assert mapped_files("libpythonfmu-export.so") | mapped_files("NpidServo.so") <= libraries
    assert len(sys.path) == path_length
    assert len(gc.get_objects()) - objects <= 40 + 10  # pythonfmu's MRO list per instantiate
    grown_kB = int(Path("/proc/self/statm").read_text().split()[1]) * 4 - resident_kB
    assert grown_kB < 40 * 50, f"{grown_kB / 40:.0f} kB per cycle (was 350)"


OMS_DIR = FMI_TOOLS / "omsimulator"


@pytest.fixture(scope="module")
def portable_ssp(fmu_paths, tmp_path_factory):
    from feedaxis.cosim.ssp import export_ssp
    from feedaxis.cosim.system import default_axis
    system = default_axis().with_steps(ThermalScrew=1e-3)
    return system, export_ssp(tmp_path_factory.mktemp("ssp") / "axis.ssp", system, fmu_paths)


def servo_position_from_master(system, fmu_paths, n_steps):
    from feedaxis.cosim.master import Master
    with Master(system, fmu_paths) as master:
        return master.run(n_steps * 1e-3, {"disturbance_N": 300.0})["NpidServo.position_mm"][-1]


def test_omsimulator_program_runs_the_ssp(portable_ssp, tmp_path):
    program = OMS_DIR / "bin" / "OMSimulator"
    require_tool(program)
    run = subprocess.run([str(program), "--stopTime=0.2", "--resultFile=result.csv",
                          str(portable_ssp[1])], cwd=tmp_path, capture_output=True, text=True,
                         timeout=300)
    errors = [line for line in (run.stdout + run.stderr).splitlines() if line.startswith("error")]
    assert run.returncode == 0 and not errors, (run.stdout + run.stderr)[-3000:]
    lines = (tmp_path / "result.csv").read_text().splitlines()
    names = [name.strip().strip('"') for name in lines[0].split(",")]
    table = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
    assert table[-1, 0] == pytest.approx(0.2)
    geometric = next(i for i, n in enumerate(names) if n.endswith("GeometricError.error_um"))
    assert table[-1, geometric] == pytest.approx(0.45106988665543396, rel=1e-12)


def test_omsimulator_python_api_and_ecospy_run_the_ssp_alike(portable_ssp, fmu_paths):
    """Two in-process hosts (OMSimulator's Python API, ecospy) against the feedaxis master:
    the servo has no input from the other FMUs, so its position agrees exactly."""
    require_tool(OMS_DIR / "lib")
    sys.path.insert(0, str(OMS_DIR / "lib" / "x86_64-linux-gnu"))
    try:
        from OMSimulator import SSP, CRef
    finally:
        sys.path.pop(0)
    system, ssp_path = portable_ssp
    instance = SSP(str(ssp_path)).instantiate()
    instance.setResultFile("")
    instance.setValue(CRef("FeedAxis", "NpidServo", "disturbance_N"), 300.0)
    instance.initialize()
    time_s = 0.0
    for _ in range(200):
        time_s += 1e-3  # cumulative targets (tools README)
        instance.stepUntil(time_s)
    oms = [instance.getValue(CRef("FeedAxis", name, output)) for name, output in
           (("NpidServo", "position_mm"), ("GeometricError", "error_um"))]
    instance.terminate()
    instance.delete()
    require_ecospy()
    from ecospy import EcosSimulation
    with EcosSimulation(step_size=1e-3, ssp_path=str(ssp_path)) as simulation:
        simulation.init(parameter_set=system.name)
        simulation.set_real("NpidServo::disturbance_N", 300.0)
        simulation.step(200)
        ecos = [simulation.get_real("NpidServo::position_mm"),
                simulation.get_real("GeometricError::error_um")]
        simulation.terminate()
    assert oms == pytest.approx(ecos, rel=1e-12)
    assert oms[0] == pytest.approx(servo_position_from_master(system, fmu_paths, 200), rel=1e-9)


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmu_readme_tables_every_variable(loaded_fmus, name):
    readme = (FMU_SOURCES / name / "README.md").read_text()
    for variable in loaded_fmus[name].description.modelVariables:
        row = f"| `{variable.name}` | {variable.causality} | {variable.type} | {variable.unit or ''} |"
        assert row in readme, row


def test_ecos_program_runs_the_ssp(portable_ssp, tmp_path):
    """ecos (ecospy's own C++ program, multi-threaded): a host that is not a Python process."""
    import shutil
    program = tmp_path / "ecos"
    shutil.copy(require_ecospy() / "binaries" / "ecos", program)  # shipped without +x
    program.chmod(0o755)
    run = subprocess.run([str(program), "simulate", "--path", str(portable_ssp[1]),
                          "--stopTime", "0.2", "--stepSize", "0.001", "--parameterSet",
                          portable_ssp[0].name], cwd=tmp_path, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, (run.stdout + run.stderr)[-3000:]
    lines = next(tmp_path.glob("*.csv")).read_text().splitlines()
    names = [name.strip() for name in lines[0].split(",")]
    last = [field.strip() for field in lines[-1].split(",")]
    assert float(last[names.index("time")]) == pytest.approx(0.2, abs=1.5e-3)  # rows may be
    # stamped with a step's start time
    geometric = names.index("GeometricError::error_um[REAL]")
    assert float(last[geometric]) == pytest.approx(0.45107, abs=1e-6)  # printed to 6 decimals


def test_container_fmu_runs_in_fmu_check(portable_ssp, fmu_paths, tmp_path):
    """fmpy's container (its own native binary loading the four FMUs) inside a C host."""
    require_tool(FMU_CHECK)
    from feedaxis.cosim.container import export_container_fmu
    container = export_container_fmu(tmp_path / "axis.fmu", portable_ssp[0], fmu_paths)
    run = subprocess.run([str(FMU_CHECK), "-k", "cs", "-s", "0.2", "-h", "0.001", "-l", "3",
                          "-o", str(tmp_path / "out.csv"), str(container)],
                         capture_output=True, text=True, timeout=300)
    report = run.stdout + run.stderr
    assert run.returncode == 0 and "0 Error(s)" in report, report[-3000:]
    assert "[ERROR]" not in report and "[FATAL]" not in report
    result = read_csv(tmp_path / "out.csv")
    assert result["GeometricError.error_um"][-1] == pytest.approx(0.45106988665543396, rel=1e-12)


def test_omsimulator_program_survives_a_bad_parameter(fmu_paths, tmp_path):
    """pythonfmu's NULL log category used to end the OMSimulator process here."""
    program = OMS_DIR / "bin" / "OMSimulator"
    require_tool(program)
    from feedaxis.cosim.ssp import export_ssp
    from feedaxis.cosim.system import default_axis
    ssp_path = export_ssp(tmp_path / "bad.ssp", default_axis().with_parameters(
        {"GeometricError": {"diameter_m": 0.0}}), fmu_paths)
    run = subprocess.run([str(program), "--stopTime=0.05", str(ssp_path)], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    report = run.stdout + run.stderr
    assert run.returncode >= 0, report[-3000:]  # not killed by a signal
    assert "logStatusError: GeometricError: initialisation: diameter_m: must be > 0" in report


def scripted_calls(loaded):
    """Every value a host reads from NpidServo over a script that mixes partial input sets,
    reads of inputs and outputs, steps, and a saved state taken with inputs not yet stepped
    and restored later: the host layer keeps inputs and outputs itself while stepping, and
    must read back exactly what pythonfmu's own library does."""
    outputs = [vr(loaded, n) for n in ("position_mm", "velocity_mm_s", "tracking_error_mm")]
    reference, force = vr(loaded, "position_ref_mm"), vr(loaded, "disturbance_N")
    slave = fresh(loaded)
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.setReal([reference], [0.5])
    slave.exitInitializationMode()
    read = [slave.getReal(outputs + [reference, force])]
    time_s, saved = 0.0, None
    for k in range(30):
        slave.setReal([reference], [0.5 + 0.02 * k])
        if k % 3 == 0:
            slave.setReal([force], [5.0 * k])
        if k == 10:
            saved = slave.getFMUstate()
        slave.doStep(time_s, 0.001)
        time_s += 0.001
        read.append(slave.getReal(outputs) + slave.getReal([force, reference]))
    slave.setFMUstate(saved)
    read.append(slave.getReal([reference, force] + outputs))
    slave.doStep(0.010, 0.001)
    read.append(slave.getReal(outputs))
    read.append([slave.getRealStatus(2)])
    slave.freeFMUstate(saved)
    slave.terminate()
    read.append(slave.getReal(outputs + [reference]))
    slave.freeInstance()
    slave.freeLibrary()
    return read


def test_host_layer_reads_back_what_pythonfmu_does(loaded_fmus, tmp_path, monkeypatch):
    from feedaxis import fmu_build
    from feedaxis.cosim.fmu_runner import LoadedFmu

    monkeypatch.setattr(fmu_build, "host_layer_missing", lambda: "no C compiler (test)")
    monkeypatch.delenv("CI", raising=False)
    with pytest.warns(UserWarning, match="Python hosts only"):
        python_only = LoadedFmu(fmu_build.build_fmu("NpidServo", tmp_path))
    try:
        expected = scripted_calls(python_only)
        got = scripted_calls(loaded_fmus["NpidServo"])
    finally:
        python_only.close()
    assert got == expected
    assert got[-3] == got[11][:3]  # the restored state steps as the saved one did
