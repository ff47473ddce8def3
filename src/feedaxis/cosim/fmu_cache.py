"""The four FMUs built once per feedaxis version and FMU source, kept in the user cache.

Building takes seconds per FMU (pythonfmu), so ``feedaxis simulate`` and ``export-ssp``
reuse ``<cache>/feedaxis/fmus-<version>-<hash>/``, where the hash covers every file that
goes into an FMU (the slave scripts, the adapter, the host layer, the physics package, the
build script):
a changed source builds a new folder, never a stale FMU. FMUs built without the C host
layer (no compiler here) or the compiled servo loop go to a folder of their own, so
installing a compiler rebuilds. The folder is built in a staging
folder and renamed into place, so a crash or Ctrl-C never leaves half a cache.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from pathlib import Path

from .. import __version__
from ..errors import InputError
from ..fmu_build import FMU_NAMES, SOURCE_DIR, build_fmus, fmu_sources, host_layer_missing
from ..kernel_build import kernel_missing


def source_hash():
    """SHA-256 (first 12 hex digits) of every source file that goes into the FMUs."""
    digest = hashlib.sha256()
    sources = fmu_sources()
    files = sorted([*sources.glob("*/*.py"), *sources.glob("common/*.c"),
                    *(SOURCE_DIR / "physics").glob("*.py"), SOURCE_DIR / "fmu_build.py",
                    SOURCE_DIR / "kernel_build.py"])
    for path in files:
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def cache_root():
    """``$XDG_CACHE_HOME/feedaxis`` (default ``~/.cache/feedaxis``)."""
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "feedaxis"


def cache_folder(root=None):
    """The cache folder of this version's FMUs (``root`` defaults to :func:`cache_root`)."""
    python_only = "-python-hosts" if host_layer_missing() else ""
    python_loop = "-python-loop" if kernel_missing() else ""  # no compiled servo loop
    return (Path(root or cache_root())
            / f"fmus-{__version__}-{source_hash()}{python_only}{python_loop}")


def cached_fmus(root=None):
    """{FMU name: path} of the four FMUs, built into the cache on first use."""
    folder = cache_folder(root)
    if not all((folder / f"{name}.fmu").exists() for name in FMU_NAMES):
        folder.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".fmus-", dir=folder.parent))
        try:
            build_fmus(staging)
            shutil.rmtree(folder, ignore_errors=True)
            os.replace(staging, folder)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    return {name: folder / f"{name}.fmu" for name in FMU_NAMES}


def fmu_paths(folder=None):
    """{FMU name: path} of the four FMUs in ``folder`` (``--fmus``), else of the cache."""
    if folder is None:
        return cached_fmus()
    paths = {name: Path(folder) / f"{name}.fmu" for name in FMU_NAMES}
    missing = [str(p) for p in paths.values() if not p.exists()]
    if missing:
        raise InputError(f"missing {', '.join(missing)}", parameter=f"--fmus {folder}")
    return paths
