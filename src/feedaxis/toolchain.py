"""What the FMU build and the servo kernel build both take from the machine: its C compiler
and the user cache folder. A floor-0 module (it imports no feedaxis module), so that
``fmu_build``, ``kernel_build`` and ``cosim.fmu_cache`` share them without importing each
other in a circle."""
from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path


def c_compiler():
    """The machine's C compiler: ``$CC``, else cc or gcc on the PATH (None without one)."""
    return os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")


def compiler_missing(what):
    """Why ``what`` cannot be compiled on this machine for want of Linux or a C compiler
    (None when it can)."""
    if not sys.platform.startswith("linux"):
        return f"{what} is built for Linux only, not {sys.platform}"
    if not c_compiler():
        return "no C compiler (cc or gcc, or set CC)"
    return None


def cache_root():
    """``$XDG_CACHE_HOME/feedaxis`` (default ``~/.cache/feedaxis``)."""
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "feedaxis"
