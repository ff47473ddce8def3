"""numba's compiled kernels are cached on disk wherever feedaxis is installed: beside the
source or in the user's cache as numba does, else in a private temporary folder, else not
at all (compiled each run, still correct)."""
import os
import tempfile

import numba
import pytest
from numba.core import caching

from feedaxis.physics.numba_cache import cached_njit, private_cache_folder


def triple(x):
    return 3.0 * x


@pytest.fixture
def no_writable_cache(monkeypatch, tmp_path):
    """numba sees no writable folder beside the source nor in the user's cache (a
    read-only site-packages, no home): only NUMBA_CACHE_DIR could help; tmp_path is the
    temporary directory."""
    implementation = getattr(caching, "CacheImpl", None) or caching._CacheImpl  # numba < 0.60
    user_provided = (getattr(caching, "UserProvidedCacheLocator", None)
                     or caching._UserProvidedCacheLocator)
    monkeypatch.setattr(implementation, "_locator_classes", [user_provided])
    monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    return tmp_path


def test_numba_alone_refuses_to_cache_there(no_writable_cache):
    with pytest.raises(RuntimeError, match="cannot cache function"):
        numba.njit(cache=True)(triple)


def test_the_kernel_is_cached_in_a_private_temporary_folder(no_writable_cache):
    compiled = cached_njit(numba, triple)
    assert compiled(2.0) == 6.0
    folder = no_writable_cache / f"feedaxis-numba-{os.getuid()}"
    assert numba.config.CACHE_DIR == str(folder)
    assert any(path.suffix == ".nbi" for path in folder.rglob("*"))
    assert folder.stat().st_mode & 0o777 == 0o700


def test_a_temporary_folder_others_may_write_is_not_used(no_writable_cache):
    folder = no_writable_cache / f"feedaxis-numba-{os.getuid()}"
    folder.mkdir(mode=0o777)
    folder.chmod(0o777)
    assert private_cache_folder() is None
    compiled = cached_njit(numba, triple)   # compiled without a cache, still runs
    assert compiled(2.0) == 6.0 and numba.config.CACHE_DIR == ""
    assert not list(folder.iterdir())
