"""Shared fixtures: the four FMUs are built once per test session."""
import shutil

import pytest

from feedaxis.cosim.fmu_cache import cache_folder
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


@pytest.fixture
def user_fmu_cache(fmu_paths, tmp_path, monkeypatch):
    """A user cache (``XDG_CACHE_HOME``) already holding this session's FMUs; its folder."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    cache = cache_folder()
    cache.mkdir(parents=True)
    for path in fmu_paths.values():
        shutil.copy2(path, cache / path.name)
    return cache
