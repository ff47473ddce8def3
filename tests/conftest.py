"""Shared fixtures: the four FMUs are built once per test session."""
import pytest

from feedaxis.cosim.fmu_runner import LoadedFmu
from feedaxis.fmu_build import FMU_NAMES, build_fmus


@pytest.fixture(scope="session")
def fmu_paths(tmp_path_factory):
    """Name -> path of each freshly built FMU."""
    out_dir = tmp_path_factory.mktemp("fmus")
    return {path.stem: path for path in build_fmus(out_dir)}


@pytest.fixture(scope="session")
def loaded_fmus(fmu_paths):
    """Name -> extracted :class:`LoadedFmu`, shared by the session."""
    loaded = {name: LoadedFmu(fmu_paths[name]) for name in FMU_NAMES}
    yield loaded
    for fmu in loaded.values():
        fmu.close()
