"""The four FMUs built once per feedaxis version and FMU source, kept in the user cache.

Building takes seconds per FMU (pythonfmu), so ``feedaxis simulate`` and ``export-ssp``
reuse ``<cache>/feedaxis/fmus-<version>-<hash>/``, where the hash covers every file that
goes into an FMU (the slave scripts, the adapter, the host layer, the physics package, the
build scripts): a changed source builds a new folder, never a stale FMU. FMUs built
without the C host layer (no compiler here) or the compiled steps go to a folder of
their own, so installing a compiler rebuilds; standalone FMUs (``export-ssp --standalone``)
too. The folder is built in a staging folder and renamed into place, so a crash or Ctrl-C
never leaves half a cache.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

from .. import __version__
from ..errors import InputError
from ..fmu_build import FMU_NAMES, SOURCE_DIR, build_fmus, fmu_sources, host_layer_missing
from ..kernel_build import kernel_missing
from ..output import built_once
from ..toolchain import cache_root
from .fmu_interface import check_fmu, intact


def source_hash():
    """SHA-256 (first 12 hex digits) of every source file that goes into the FMUs."""
    digest = hashlib.sha256()
    sources = fmu_sources()
    files = sorted([*sources.glob("*/*.py"), *sources.glob("common/host/*.[ch]"),
                    *sources.glob("common/fmi[23]/*.h"), *(SOURCE_DIR / "physics").glob("*.py"),
                    *(SOURCE_DIR / name for name in ("fmu_build.py", "fmu_standalone.py",
                                                     "fmu_fmi3.py", "fmu_trace.py",
                                                     "kernel_build.py"))])
    for path in files:
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def cache_folder(root=None, standalone=False, fmi=2):
    """The cache folder of this version's FMUs (``root`` defaults to :func:`cache_root`);
    standalone FMUs (:mod:`feedaxis.fmu_standalone`) have their own, and so have FMI 3.0
    FMUs and FMUs without the C host layer or the compiled steps."""
    kind = "-standalone" if standalone else "-python-hosts" if host_layer_missing() else ""
    version = "-fmi3" if fmi == 3 else ""
    python_loop = "-python-loop" if kernel_missing() else ""
    return Path(root or cache_root()) / (f"fmus-{__version__}-{source_hash()}{version}{kind}"
                                         f"{python_loop}")


def cached_fmus(root=None, standalone=False, fmi=2):
    """{FMU name: path} of the four FMUs (``standalone``: carrying their Python; ``fmi``: 2
    or 3), built into the cache on first use."""
    folder = built_once(cache_folder(root, standalone, fmi),
                        lambda staging: build_fmus(staging, standalone=standalone, fmi=fmi),
                        _complete)
    return {name: folder / f"{name}.fmu" for name in FMU_NAMES}


def _complete(folder):
    """Whether the cache folder holds the four FMUs, each opening with the interface the
    axis needs (:func:`.fmu_interface.intact`): a truncated or emptied one is rebuilt."""
    return intact({name: folder / f"{name}.fmu" for name in FMU_NAMES})


def fmu_paths(folder=None, standalone=False, fmi=None):
    """{FMU name: path} of the four FMUs in ``folder`` (``--fmus``: each checked to be a safe
    FMU archive with the interface the axis needs), else of the cache; ``standalone``: FMUs
    that carry their Python (those in ``folder`` must be); ``fmi``: the FMI major version
    asked for (``--fmi``: those in ``folder`` must be of it; the cache's default is 2)."""
    if folder is None:
        return cached_fmus(standalone=standalone, fmi=fmi or 2)
    paths = {name: Path(folder) / f"{name}.fmu" for name in FMU_NAMES}
    missing = [str(p) for p in paths.values() if not p.exists()]
    if missing:
        raise InputError(f"missing {', '.join(missing)}", parameter=f"--fmus {folder}")
    for name, path in paths.items():
        version = check_fmu(path, name).fmiVersion
        if fmi is not None and not version.startswith(f"{fmi}."):
            raise InputError(f"an FMI {version} FMU, and --fmi {fmi} asks for FMI {fmi}.0 "
                             f"(build them with build-fmus --fmi {fmi})", path=path)
    if standalone:
        from ..fmu_standalone import is_standalone

        plain = [str(p) for p in paths.values() if not is_standalone(p)]
        if plain:
            raise InputError(f"not standalone: {', '.join(plain)} (build them with "
                             "build-fmus --standalone)", parameter=f"--fmus {folder}")
    return paths
