"""The four FMUs built once per feedaxis version and FMU source, kept in the user cache.

Building takes seconds per FMU (pythonfmu), so ``feedaxis simulate`` and ``export-ssp``
reuse ``<cache>/feedaxis/fmus-<version>-<hash>/``, where the hash covers every file that
goes into an FMU (the slave scripts, the adapter, the host layer, the physics package, the
build scripts): a changed source builds a new folder, never a stale FMU. FMUs built
without the C host layer (no compiler here) or the compiled servo loop go to a folder of
their own, so installing a compiler rebuilds; standalone FMUs (``export-ssp --standalone``)
too. The folder is built in a staging folder and renamed into place, so a crash or Ctrl-C
never leaves half a cache.
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
from ..output import writing
from ..toolchain import cache_root  # also imported from here (tests, benchmarks)
from .fmu_runner import check_fmu_archive
from ..kernel_build import kernel_missing


def source_hash():
    """SHA-256 (first 12 hex digits) of every source file that goes into the FMUs."""
    digest = hashlib.sha256()
    sources = fmu_sources()
    files = sorted([*sources.glob("*/*.py"), *sources.glob("common/*.c"),
                    *sources.glob("common/fmi2/*.h"), *(SOURCE_DIR / "physics").glob("*.py"),
                    *(SOURCE_DIR / name for name in ("fmu_build.py", "fmu_standalone.py",
                                                     "fmu_trace.py", "kernel_build.py"))])
    for path in files:
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def cache_folder(root=None, standalone=False):
    """The cache folder of this version's FMUs (``root`` defaults to :func:`cache_root`);
    standalone FMUs (:mod:`feedaxis.fmu_standalone`) have their own, and so have FMUs
    without the C host layer or the compiled servo loop."""
    kind = "-standalone" if standalone else "-python-hosts" if host_layer_missing() else ""
    python_loop = "-python-loop" if kernel_missing() else ""
    return Path(root or cache_root()) / f"fmus-{__version__}-{source_hash()}{kind}{python_loop}"


def cached_fmus(root=None, standalone=False):
    """{FMU name: path} of the four FMUs (``standalone``: carrying their Python), built into
    the cache on first use."""
    folder = cache_folder(root, standalone)
    if not _complete(folder):
        with writing(folder):
            folder.parent.mkdir(parents=True, exist_ok=True)
            staging = Path(tempfile.mkdtemp(prefix=".fmus-", dir=folder.parent))
            try:
                build_fmus(staging, standalone=standalone)
                if folder.exists() and not _complete(folder):
                    shutil.rmtree(folder, ignore_errors=True)
                _publish(staging, folder)
            finally:
                shutil.rmtree(staging, ignore_errors=True)
    return {name: folder / f"{name}.fmu" for name in FMU_NAMES}


def _complete(folder):
    return all((folder / f"{name}.fmu").exists() for name in FMU_NAMES)


def _publish(staging, folder):
    """Rename ``staging`` to ``folder``; a run that built the same cache meanwhile keeps its
    folder (a rename never replaces a folder holding files), and this one uses it."""
    try:
        os.replace(staging, folder)
    except OSError:
        if not _complete(folder):
            raise


def fmu_paths(folder=None, standalone=False):
    """{FMU name: path} of the four FMUs in ``folder`` (``--fmus``: each checked to be a safe
    FMU archive), else of the cache; ``standalone``: FMUs that carry their Python (those in
    ``folder`` must be)."""
    if folder is None:
        return cached_fmus(standalone=standalone)
    paths = {name: Path(folder) / f"{name}.fmu" for name in FMU_NAMES}
    missing = [str(p) for p in paths.values() if not p.exists()]
    if missing:
        raise InputError(f"missing {', '.join(missing)}", parameter=f"--fmus {folder}")
    for path in paths.values():
        check_fmu_archive(path)
    if standalone:
        from ..fmu_standalone import is_standalone

        plain = [str(p) for p in paths.values() if not is_standalone(p)]
        if plain:
            raise InputError(f"not standalone: {', '.join(plain)} (build them with "
                             "build-fmus --standalone)", parameter=f"--fmus {folder}")
    return paths
