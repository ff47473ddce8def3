"""Shared fixtures (the four FMUs are built once per test session) and the one rule for a
test that needs something outside pip: it skips with the reason on a developer's machine
and fails under CI (``CI=true``), whose ``.ci/run`` installs it."""
import ctypes
import importlib.machinery
import importlib.util
import os
import shutil
import signal
import sys
from pathlib import Path

import pytest

from feedaxis import kernel_build
from feedaxis.cosim.fmu_cache import cache_folder
from feedaxis.toolchain import cache_root
from feedaxis.cosim.fmu_runner import LoadedFmu
from feedaxis.fmu_build import FMU_NAMES, build_fmus

# The tests sit in one folder per layer; the helpers (synthetic.py, scenarios.py, toy_kind.py
# ...) in this one, which pytest puts on sys.path with this file. A few test modules share
# tables with others (test_seed_reproduction's published figures, test_fuzz's strategies):
# every layer's folder is importable too, whichever test is collected first.
sys.path[:0] = [str(folder) for folder in sorted(Path(__file__).resolve().parent.iterdir())
                if folder.is_dir() and any(folder.glob("test_*.py"))]

# System libraries tests load, and how to install them (Debian 12, as .ci/run does).
SYSTEM_LIBRARIES = {"libtbb.so.12": "apt-get install libtbb12 (ecospy's ecos needs it)"}
# The FMI hosts that are not Python processes (fmuCheck.linux64, omsimulator/): the folder
# $FEEDAXIS_FMI_TOOLS names, else where the CI machine keeps them, beside the checkout.
# docs/fmu-hosts.md ("The hosts the tests use") says how to get them.
FMI_TOOLS = Path(os.environ.get("FEEDAXIS_FMI_TOOLS")
                 or Path(__file__).resolve().parents[2] / "shared" / "tools" / "fmi")


def unavailable(reason):
    """Skip the calling test with ``reason``; under CI (``CI=true``) fail it instead: CI
    installs everything the suite needs, so a missing piece there is an error."""
    if os.environ.get("CI") == "true":
        pytest.fail(f"{reason}; CI must provide it (.ci/run installs it)")
    pytest.skip(reason)


def require_tool(path):
    """Skip (fail under CI) unless the FMI host ``path`` of ``FMI_TOOLS`` exists, saying
    where the tests look for it."""
    if not Path(path).exists():
        unavailable(f"{path} is missing: set FEEDAXIS_FMI_TOOLS to the folder of the FMI hosts "
                    "(docs/fmu-hosts.md, 'The hosts the tests use')")


def require_system_library(soname):
    """Skip (fail under CI) unless the dynamic loader finds the system library ``soname``,
    naming how to install it (``SYSTEM_LIBRARIES``)."""
    try:
        ctypes.CDLL(soname)
    except OSError as error:
        unavailable(f"the system library {soname} cannot be loaded ({error}); install: "
                    f"{SYSTEM_LIBRARIES.get(soname, 'the package providing it')}")


@pytest.fixture(autouse=True)
def python_sigint_handler():
    """Every test starts with Python's own Ctrl-C handler and leaves the handler as it found
    it: a test of the console script (which ignores SIGINT on its way out) must not change
    what a later test in the same process (an xdist worker) sees when it raises SIGINT."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.fixture(scope="session")
def fmu_paths(tmp_path_factory):
    """Name -> path of each freshly built FMU."""
    out_dir = tmp_path_factory.mktemp("fmus")
    return {path.stem: path for path in build_fmus(out_dir)}


@pytest.fixture(scope="session")
def fmi3_paths(tmp_path_factory):
    """Name -> path of each freshly built FMI 3.0 FMU (``build-fmus --fmi 3``)."""
    return {path.stem: path for path in build_fmus(tmp_path_factory.mktemp("fmi3"), fmi=3)}


@pytest.fixture(scope="session")
def loaded_fmus(fmu_paths):
    """Name -> extracted :class:`LoadedFmu`, shared by the session."""
    loaded = {name: LoadedFmu(fmu_paths[name]) for name in FMU_NAMES}
    yield loaded
    for fmu in loaded.values():
        fmu.close()


@pytest.fixture
def user_fmu_cache(fmu_paths, tmp_path, monkeypatch):
    """A user cache (``XDG_CACHE_HOME``) already holding this session's FMUs; its folder."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    cache = cache_folder()
    cache.mkdir(parents=True)
    for path in fmu_paths.values():
        shutil.copy2(path, cache / path.name)
    return cache


@pytest.fixture(scope="session")
def compiled_servo_loop():
    """physics.servo.run_loop compiled ahead of time as the NpidServo FMU carries it
    (feedaxis.kernel_build, the user cache); skips without a compiler, fails under CI."""
    missing = kernel_build.kernel_missing()
    if missing is not None:
        unavailable(f"the servo kernel cannot be compiled here: {missing}")
    path = kernel_build.cached_kernel(cache_root())
    loader = importlib.machinery.ExtensionFileLoader(kernel_build.MODULE_NAME, str(path))
    module = importlib.util.module_from_spec(
        importlib.util.spec_from_loader(kernel_build.MODULE_NAME, loader))
    loader.exec_module(module)
    return module.run_loop
