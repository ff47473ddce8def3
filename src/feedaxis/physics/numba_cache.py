"""numba's on-disk cache wherever feedaxis is installed, so a compiled kernel is compiled once.

numba caches a compiled function beside its source (``__pycache__``) when that folder is
writable, else in the user's cache folder (``$XDG_CACHE_HOME/numba`` or ``~/.cache/numba``);
with neither (a read-only site-packages and no writable home) it refuses to cache at all.
:func:`cached_njit` then caches in a folder of the temporary directory owned by the user,
and when that cannot be had either compiles without a cache (each process compiles anew,
about 6 s for the servo loop, but runs).
"""
from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

NO_LOCATOR = "cannot cache function"  # numba's RuntimeError when no cache folder is writable


def cached_njit(numba, function, **options):
    """``numba.njit(cache=True, **options)(function)``, cached in a private temporary folder
    (:func:`private_cache_folder`) when numba has no writable cache folder, not cached when
    there is none."""
    try:
        return numba.njit(cache=True, **options)(function)
    except RuntimeError as error:
        if NO_LOCATOR not in str(error):
            raise
    folder = private_cache_folder()
    if folder is not None:
        numba.config.CACHE_DIR = str(folder)
        try:
            return numba.njit(cache=True, **options)(function)
        except RuntimeError as error:
            if NO_LOCATOR not in str(error):
                raise
        numba.config.CACHE_DIR = ""
    return numba.njit(**options)(function)


def private_cache_folder():
    """``<temp>/feedaxis-numba-<uid>``, created for the user alone (mode 0700); None when it
    cannot be created or belongs to someone else or others may write to it (numba's cache
    files are pickles: loading another user's would run their code)."""
    uid = os.getuid() if hasattr(os, "getuid") else None
    folder = Path(tempfile.gettempdir()) / f"feedaxis-numba-{uid if uid is not None else 'user'}"
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        status = folder.lstat()
    except OSError:
        return None
    if not stat.S_ISDIR(status.st_mode) or (uid is not None and status.st_uid != uid) \
            or status.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return None
    return folder
