"""Standalone FMUs (issue 22): each carries the Python its physics needs, in FMI 2.0 and FMI
3.0 (issue 34).

The proofs run the FMUs in a root file system the test makes: glibc, libgcc_s, libstdc++
and the dynamic loader, no Python (``chroot``, which needs root; skipped with the reason
elsewhere, failed in CI). The standalone FMUs are built once for the module, through the
CLI (``build-fmus --standalone``, ``build-fmus --standalone --fmi 3``).
"""
import contextlib
import importlib.util
import io
import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.util import read_csv

from feedaxis.cli import main
from feedaxis.fmu_build import FMU_NAMES, binaries_platform, host_layer_missing
from feedaxis.fmu_standalone import patchelf_program, runtime_root, standalone_missing
from test_fmi3 import fmi3_instantiate_cases
from test_fmi_contract import (c_host_instantiate, check_instantiate_answer, compile_c_host,
                               instantiate_cases)
from test_fmus import assert_carries_one_platform
from test_fmi_hosts import (FMU_CHECK, FMU_SOURCES, OMS_DIR, assert_cross_check_passed,
                            cross_check_command, cross_check_options, require_tool)

GLIBC = ("libc.so.6", "libm.so.6", "libdl.so.2", "libpthread.so.0", "librt.so.1",
         "libutil.so.1", "libresolv.so.2", "libanl.so.1", "libmvec.so.1")
GCC_RUNTIME = ("libgcc_s.so.1", "libstdc++.so.6")
LOADER = Path("/lib64/ld-linux-x86-64.so.2")
LIBRARIES = "lib/x86_64-linux-gnu"


def skip_or_fail(reason):
    if os.environ.get("CI") == "true":
        pytest.fail(f"{reason} (required in CI)")
    pytest.skip(reason)


def cli(*argv):
    """Run the feedaxis CLI in this process; (exit code, stdout)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(list(argv))
    return code, out.getvalue()


def build_standalone(folder, *options):
    """Name -> path of each standalone FMU built by ``build-fmus --standalone [options]``."""
    missing = standalone_missing() or host_layer_missing()
    if missing:
        skip_or_fail(f"cannot build standalone FMUs here: {missing}")
    code, out = cli("build-fmus", "--standalone", *options, "--out", str(folder), "--json")
    assert code == 0, out
    return {Path(path).stem: Path(path) for path in json.loads(out)}


@pytest.fixture(scope="module")
def standalone(tmp_path_factory):
    """Name -> path of each standalone FMU, built by ``build-fmus --standalone``."""
    return build_standalone(tmp_path_factory.mktemp("sa"))


@pytest.fixture(scope="module")
def standalone3(tmp_path_factory):
    """Name -> path of each standalone FMI 3.0 FMU (``build-fmus --standalone --fmi 3``)."""
    return build_standalone(tmp_path_factory.mktemp("sa3"), "--fmi", "3")


def library_path(soname):
    """Where this machine's loader cache puts ``soname`` (x86-64)."""
    listing = subprocess.run([shutil.which("ldconfig") or "/sbin/ldconfig", "-p"],
                             capture_output=True, text=True, check=True).stdout
    for line in listing.splitlines():
        name, _, path = line.strip().partition(" => ")
        if name.split()[0] == soname and "x86-64" in name:
            return Path(path)
    raise FileNotFoundError(soname)


def make_root(folder, libraries=()):
    """A root file system with glibc, libgcc_s, libstdc++, the loader, ``libraries`` (paths)
    and an empty /tmp: no Python."""
    if not sys.platform.startswith("linux") or os.geteuid() != 0 or not shutil.which("chroot"):
        skip_or_fail("a root file system without Python needs Linux, root and chroot")
    (folder / LIBRARIES).mkdir(parents=True)
    (folder / "lib64").mkdir()
    (folder / "tmp").mkdir()
    for library in [*map(library_path, GLIBC + GCC_RUNTIME), *libraries]:
        shutil.copy2(Path(library).resolve(), folder / LIBRARIES / Path(library).name)
    shutil.copy2(LOADER.resolve(), folder / "lib64" / LOADER.name)
    assert not [p for p in folder.rglob("*") if "python" in p.name.lower()]
    return folder


def chroot(root, *command, timeout=300):
    return subprocess.run(["chroot", str(root), *command], capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def bare_root(tmp_path_factory):
    return make_root(tmp_path_factory.mktemp("root"))


@pytest.mark.parametrize("name", FMU_NAMES)
def test_fmu_check_runs_each_standalone_fmu_in_a_root_without_python(standalone, bare_root,
                                                                     name):
    require_tool(FMU_CHECK)
    shutil.copy2(FMU_CHECK, bare_root / FMU_CHECK.name)
    shutil.copy2(standalone[name], bare_root / f"{name}.fmu")
    shutil.copy2(FMU_SOURCES / name / f"{name}_in.csv", bare_root / f"{name}_in.csv")
    (bare_root / "tmp" / name).mkdir()
    # -z: unpack into a given folder (fmuCheck removes its own temporary one with rm)
    run = chroot(bare_root, *cross_check_command(
        name, f"/{name}_in.csv", f"/{name}_out.csv", f"/{name}.fmu", f"/{FMU_CHECK.name}",
        extra=("-z", f"/tmp/{name}")))
    assert_cross_check_passed(name, run, bare_root / f"{name}_out.csv")


@pytest.mark.parametrize("fmi", (2, 3))
def test_omsimulator_runs_the_standalone_ssp_in_a_root_without_python(request, tmp_path, fmi):
    """The program's own libraries (ldd) join the root, and /proc: OMSimulator reads
    /proc/self/maps and ends with a segmentation fault without it. FMI 3.0: ``export-ssp
    --fmi 3 --standalone`` of the standalone FMI 3.0 FMUs."""
    program = OMS_DIR / "bin" / "OMSimulator"
    require_tool(program)
    standalone = request.getfixturevalue("standalone" if fmi == 2 else "standalone3")
    listing = subprocess.run(["ldd", str(program)], capture_output=True, text=True).stdout
    own = [line.split(" => ")[1].split()[0] for line in listing.splitlines() if " => /" in line
           and line.split()[0] not in GLIBC + GCC_RUNTIME]
    root = make_root(tmp_path / "root", own)
    shutil.copytree(OMS_DIR, root / "oms")
    code, out = cli("export-ssp", str(root / "axis.ssp"), "--standalone", "--fmi", str(fmi),
                    "--fmus", str(standalone["NpidServo"].parent), "--json")
    assert code == 0 and json.loads(out)["open_inputs"][0]["input"] == "NpidServo.position_ref_mm"
    (root / "proc").mkdir()
    if subprocess.run(["mount", "-t", "proc", "proc", str(root / "proc")]).returncode != 0:
        skip_or_fail("cannot mount /proc in the root")
    try:
        run = chroot(root, "/oms/bin/OMSimulator", "--stopTime=0.2",
                     "--resultFile=/tmp/result.csv", "/axis.ssp")
    finally:
        subprocess.run(["umount", str(root / "proc")], check=True)
    errors = [line for line in (run.stdout + run.stderr).splitlines() if line.startswith("error")]
    assert run.returncode == 0 and not errors, (run.stdout + run.stderr)[-3000:]
    lines = (root / "tmp" / "result.csv").read_text().splitlines()
    names = [name.strip().strip('"') for name in lines[0].split(",")]
    table = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
    assert table[-1, 0] == pytest.approx(0.2)
    geometric = next(i for i, n in enumerate(names) if n.endswith("GeometricError.error_um"))
    assert table[-1, geometric] == pytest.approx(0.45106988665543396, rel=1e-12)


@pytest.mark.parametrize("name", FMU_NAMES)
@pytest.mark.parametrize("fmi", (2, 3))
def test_fmpy_gives_the_same_outputs_standalone_or_not(request, name, fmi):
    alone, not_alone = (request.getfixturevalue(fixture) for fixture in (
        ("standalone", "fmu_paths") if fmi == 2 else ("standalone3", "fmi3_paths")))
    options = cross_check_options(name)
    inputs = read_csv(FMU_SOURCES / name / f"{name}_in.csv")
    runs = [simulate_fmu(str(path), stop_time=options["StopTime"], step_size=options["StepSize"],
                         input=inputs) for path in (alone[name], not_alone[name])]
    for output in runs[1].dtype.names:
        np.testing.assert_array_equal(runs[0][output], runs[1][output])


@pytest.fixture(scope="module")
def c_host(bare_root):
    """The FMI 2.0 C host of the tests compiled into the root (it needs only glibc)."""
    return compile_c_host(bare_root / "fmi_c_host")


@pytest.fixture(scope="module")
def c_host3(bare_root):
    """The FMI 3.0 C host of the tests compiled into the root (it needs only glibc)."""
    return compile_c_host(bare_root / "fmi3_c_host", fmi=3)


def c_host_command(fmu_path, unpacked, outputs, n_instances=2, n_steps=300, inputs=None):
    """Arguments of tests/fmi_c_host.c: ``n_steps`` of 1 ms with ``inputs`` ({name: value};
    default: the first input at 1)."""
    description = read_model_description(str(fmu_path))
    variables = list(description.modelVariables)
    if inputs is None:
        inputs = {next(v.name for v in variables if v.causality == "input"): 1.0}
    return [str(unpacked), description.coSimulation.modelIdentifier, description.guid, "0.001",
            str(n_steps), str(n_instances),
            ",".join(f"{v.valueReference}={inputs[v.name]!r}" for v in variables
                     if v.name in inputs),
            ",".join(str(v.valueReference) for v in variables if v.name in outputs)]


def outputs_of(run):
    assert run.returncode == 0, run.stdout[-2000:]
    return [line.split()[1:] for line in run.stdout.splitlines() if line.startswith("output")]


def test_two_instances_of_a_standalone_fmu_in_a_c_host_without_python(standalone, fmu_paths,
                                                                      bare_root, c_host,
                                                                      tmp_path):
    """A C host (tests/fmi_c_host.c) steps two instances of NpidServo in the root, as the
    same host does with the FMU that uses this machine's Python."""
    outputs = ("position_mm", "velocity_mm_s")
    for path, unpacked in ((standalone["NpidServo"], bare_root / "tmp" / "servo"),
                           (fmu_paths["NpidServo"], tmp_path / "servo")):
        with zipfile.ZipFile(path) as archive:
            archive.extractall(unpacked)
    alone = outputs_of(chroot(bare_root, "/fmi_c_host", *c_host_command(
        standalone["NpidServo"], "/tmp/servo", outputs)))
    not_alone = outputs_of(subprocess.run(
        [str(c_host), *c_host_command(fmu_paths["NpidServo"], tmp_path / "servo", outputs)],
        capture_output=True, text=True))
    by_instance = {i: [v for k, _, v in alone if k == i] for i in ("0", "1")}
    assert by_instance["0"] == by_instance["1"] and float(by_instance["0"][0]) > 0.5
    assert alone == not_alone


@pytest.mark.parametrize("fmi", (2, 3))
def test_a_standalone_fmu_answers_every_instantiate_argument_in_a_root_without_python(
        request, bare_root, fmi):
    """The C host of the tests in FMI version ``fmi``, in the root without Python, instantiates
    the standalone NpidServo (one process per case): FMI 2.0 with every resource-URI form, a
    NULL name, a wrong GUID, a missing folder; FMI 3.0 with the resource path with and without
    its final '/', missing, relative, a URI, NULL, a NULL or empty name, a wrong or NULL
    instantiation token. An instance that steps, or NULL and an error saying why; never a
    signal (a bad location used to be a segmentation fault)."""
    fmu_path = request.getfixturevalue("standalone" if fmi == 2 else "standalone3")["NpidServo"]
    host = request.getfixturevalue("c_host" if fmi == 2 else "c_host3")
    cases, function = ((instantiate_cases, "fmi2Instantiate") if fmi == 2
                       else (fmi3_instantiate_cases, "fmi3InstantiateCoSimulation"))
    inside = Path("/tmp") / f"servo{fmi} dé#"
    with zipfile.ZipFile(fmu_path) as archive:
        archive.extractall(bare_root / inside.relative_to("/"))
    for case in cases(inside, read_model_description(str(fmu_path)).guid):
        check_instantiate_answer(case, *c_host_instantiate(
            ["chroot", str(bare_root), f"/{host.name}"], case, inside, "NpidServo"),
            function=function)


# Inputs that move every FMU's outputs (a moving, heated screw; a commanded, loaded servo)
MOVING = {"position_ref_mm": 1.0, "disturbance_N": 30.0, "position_mm": 5.0,
          "velocity_mm_s": 50.0, "ambient_C": 25.0}


def outputs_in_root(root, host, fmu_path, folder_name):
    """[instance, value reference, value] of each output of ``fmu_path`` unpacked in the
    root's /tmp/``folder_name``, stepped by the C host ``host`` (a program in the root) with
    :func:`c_host_command`'s run, its inputs at :data:`MOVING`."""
    with zipfile.ZipFile(fmu_path) as archive:
        archive.extractall(root / "tmp" / folder_name)
    variables = read_model_description(str(fmu_path)).modelVariables
    outputs = [v.name for v in variables if v.causality == "output"]
    inputs = {v.name: MOVING[v.name] for v in variables if v.causality == "input"}
    return outputs_of(chroot(root, f"/{host.name}", *c_host_command(
        fmu_path, f"/tmp/{folder_name}", outputs, inputs=inputs)))


@pytest.mark.parametrize("name", FMU_NAMES)
def test_each_standalone_fmi3_fmu_runs_in_an_fmi3_c_host_in_a_root_without_python(
        standalone, standalone3, bare_root, c_host, c_host3, name):
    """The FMI 3.0 C host of the tests (fmi3InstantiateCoSimulation, fmi3DoStep ...) steps two
    instances of the standalone FMI 3.0 FMU in the root: every output the standalone FMI 2.0
    FMU gives in the FMI 2.0 C host there, to 1e-12."""
    three = outputs_in_root(bare_root, c_host3, standalone3[name], f"{name}-fmi3")
    two = outputs_in_root(bare_root, c_host, standalone[name], f"{name}-fmi2")
    assert [row[:2] for row in three] == [row[:2] for row in two] and len(two) >= 2
    values = np.array([[float(row[2]) for row in run] for run in (three, two)])
    np.testing.assert_allclose(values[0], values[1], rtol=0, atol=1e-12)
    assert np.all(values[0] != 0.0)


def test_a_standalone_fmu_ignores_the_pythons_of_the_machine_it_runs_on(standalone, c_host,
                                                                        tmp_path):
    """Outside the root, with a virtual environment's python first on PATH and Python's
    variables pointing elsewhere, a C host still gets the FMU's own Python: it starts
    isolated, its program name inside the FMU (a bare one would be looked up on PATH and
    the environment found there would become its prefix, without the FMU's packages)."""
    with zipfile.ZipFile(standalone["StepperError"]) as archive:
        archive.extractall(tmp_path / "motor")
    environment = dict(os.environ, PATH=f"{Path(sys.executable).parent}:{os.environ['PATH']}",
                       PYTHONHOME="/nonexistent", PYTHONPATH="/nonexistent",
                       VIRTUAL_ENV=sys.prefix)
    run = subprocess.run([str(c_host), *c_host_command(standalone["StepperError"],
                                                        tmp_path / "motor", ("error_um",))],
                         capture_output=True, text=True, env=environment)
    assert len(outputs_of(run)) == 2


def test_standalone_fmus_of_every_kind_share_a_python_host(standalone, fmu_paths):
    """The project's master (this Python process) runs the axis of four standalone FMUs as
    it runs the others, and two instances of one standalone FMU alive at once step as two
    of the other build do."""
    from feedaxis.cosim.master import Master
    from feedaxis.cosim.system import default_axis

    system = default_axis().with_steps(ThermalScrew=1e-3)
    results = []
    for paths in (standalone, fmu_paths):
        with Master(system, paths) as master:
            results.append(master.run(0.05, {"position_ref_mm": 1.0, "disturbance_N": 30.0}))
    for column in results[1].dtype.names:
        np.testing.assert_array_equal(results[0][column], results[1][column])
    positions_mm = {"a": np.linspace(0.0, 0.5, 20), "b": np.linspace(3.0, 1.0, 20)}
    np.testing.assert_array_equal(step_two_instances(standalone["StepperError"], positions_mm),
                                  step_two_instances(fmu_paths["StepperError"], positions_mm))


def step_two_instances(path, positions_mm):
    """StepperError's error_um for each position, two instances alive and stepped in turn."""
    from fmpy import extract
    from fmpy.fmi2 import FMU2Slave

    unzipped = extract(str(path))
    description = read_model_description(unzipped)
    vr = {v.name: v.valueReference for v in description.modelVariables}
    slaves = {name: FMU2Slave(guid=description.guid, unzipDirectory=unzipped,
                              modelIdentifier=description.coSimulation.modelIdentifier,
                              instanceName=name) for name in positions_mm}
    errors_um = {name: [] for name in positions_mm}
    try:
        for slave in slaves.values():
            slave.instantiate()
            slave.setupExperiment(startTime=0.0)
            slave.enterInitializationMode()
            slave.exitInitializationMode()
        for k in range(len(positions_mm["a"])):
            for name, slave in slaves.items():
                slave.setReal([vr["position_mm"]], [positions_mm[name][k]])
                slave.doStep(k * 0.01, 0.01)
                errors_um[name] += slave.getReal([vr["error_um"]])
    finally:
        for slave in slaves.values():
            slave.terminate()
            slave.freeInstance()
        shutil.rmtree(unzipped, ignore_errors=True)
    return np.array([errors_um[name] for name in positions_mm])


# numpy is the one package every FMU's step path imports (scipy no longer: the servo's matrix
# exponential is its own), and fmpy imports numpy itself: this host calls the FMU through
# ctypes alone, as a Python host without numpy would.
HOST_WITHOUT_NUMPY = """
import ctypes, sys, tempfile, zipfile
import xml.etree.ElementTree as ET
from importlib.abc import MetaPathFinder
from pathlib import Path


class HideNumpy(MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] == "numpy":
            raise ModuleNotFoundError(name)


sys.meta_path.insert(0, HideNumpy())
folder = Path(tempfile.mkdtemp())
with zipfile.ZipFile(sys.argv[1]) as archive:
    archive.extractall(folder)
description = ET.parse(folder / "modelDescription.xml").getroot()
identifier = description.find("CoSimulation").get("modelIdentifier")
Logger = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                          ctypes.c_char_p)


class Callbacks(ctypes.Structure):
    _fields_ = [("logger", Logger), ("allocateMemory", ctypes.c_void_p),
                ("freeMemory", ctypes.c_void_p), ("stepFinished", ctypes.c_void_p),
                ("componentEnvironment", ctypes.c_void_p)]


libc = ctypes.CDLL(None)
logger = Logger(lambda env, name, status, category, message: print(message.decode()))
callbacks = Callbacks(logger, ctypes.cast(libc.calloc, ctypes.c_void_p),
                      ctypes.cast(libc.free, ctypes.c_void_p), None, None)
fmu = ctypes.CDLL(str(folder / "binaries" / "linux64" / f"{identifier}.so"))
fmu.fmi2Instantiate.restype = ctypes.c_void_p
component = fmu.fmi2Instantiate(b"host", 1, description.get("guid").encode(),
                                (folder / "resources").as_uri().encode(),
                                ctypes.byref(callbacks), 0, 0)
print("failed:" if component is None else "instantiated")
"""


def test_a_python_host_lacking_a_module_the_fmu_needs_gets_its_name(standalone):
    run = subprocess.run([sys.executable, "-c", HOST_WITHOUT_NUMPY, str(standalone["NpidServo"])],
                         capture_output=True, text=True, timeout=120)
    assert "cannot import numpy, which this FMU needs" in run.stdout, run.stdout + run.stderr
    assert "failed:" in run.stdout


@pytest.mark.parametrize("fmi", (2, 3))
def test_each_standalone_fmu_declares_only_the_platform_it_carries(request, fmi):
    """Its Python and every library that Python needs are x86-64 Linux files in the one
    binaries folder of its FMI version."""
    for path in request.getfixturevalue("standalone" if fmi == 2 else "standalone3").values():
        assert_carries_one_platform(path, binaries_platform(fmi))


@pytest.mark.parametrize("fmi", (2, 3))
def test_a_standalone_fmu_holds_no_path_of_the_build_machine(request, tmp_path, fmi):
    """Every shared library searches only its own FMU folder ($ORIGIN); the host layer
    names no interpreter or library of this machine."""
    fmu_path = request.getfixturevalue("standalone" if fmi == 2 else "standalone3")["NpidServo"]
    with zipfile.ZipFile(fmu_path) as archive:
        archive.extractall(tmp_path)
    platform = binaries_platform(fmi)
    libraries = [p for p in (tmp_path / runtime_root(platform)).rglob("*.so*") if p.is_file()]
    assert len(libraries) > 20
    for library in libraries:
        search = subprocess.run([patchelf_program(), "--print-rpath", str(library)],
                                capture_output=True, text=True, check=True).stdout.strip()
        assert all(entry.startswith("$ORIGIN") for entry in search.split(":") if entry), (
            library, search)
    layer = (tmp_path / "binaries" / platform / "NpidServo.so").read_bytes()
    for path in {sys.prefix, sys.base_prefix, sys.executable}:
        assert path.encode() not in layer


def load_runtime_module():
    """A fresh copy of fmus/common/feedaxis_fmu_runtime.py."""
    spec = importlib.util.spec_from_file_location(
        "runtime_under_test", FMU_SOURCES / "common" / "feedaxis_fmu_runtime.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_runtimes_built_differently_refuse_to_share_an_interpreter(tmp_path, monkeypatch):
    runtime = load_runtime_module()
    monkeypatch.setattr(sys, "path", list(sys.path))
    monkeypatch.setattr(sys, "meta_path", list(sys.meta_path))
    manifests = {"a": {"python": "3.11.7", "packages": {"numpy": "2.4.6"}},
                 "b": {"python": "3.11.7", "packages": {"numpy": "2.4.6", "scipy": "1.17.1"}},
                 "c": {"python": "3.11.7", "packages": {"numpy": "2.3.0"}}}
    for name, manifest in manifests.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / runtime.MANIFEST).write_text(json.dumps(manifest))
    runtime.join(str(tmp_path / "a"))
    runtime.join(str(tmp_path / "b"))  # scipy only here: fine
    with pytest.raises(ImportError, match=r"numpy 2\.3\.0 / 2\.4\.6"):
        runtime.join(str(tmp_path / "c"))
    assert runtime.JoinedRuntimes in sys.meta_path
    assert str(tmp_path / "b" / "lib" / f"python{sys.version_info.major}."
               f"{sys.version_info.minor}" / "site-packages") in sys.path


def test_building_standalone_fmus_without_the_tools_is_refused(monkeypatch, tmp_path):
    from feedaxis import fmu_standalone
    monkeypatch.setattr(fmu_standalone, "standalone_missing", lambda: "patchelf is not installed")
    code, out = cli("build-fmus", "--standalone", "--out", str(tmp_path), "--json")
    assert code == 2
    assert json.loads(out)["parameter"] == "--standalone"
    assert "patchelf is not installed" in json.loads(out)["error"]
