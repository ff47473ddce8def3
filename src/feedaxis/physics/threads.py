"""One BLAS thread for the library's small dense solves, pinned in one place.

The fits, the diagnosis and the thermal closed form solve many small matrices (3 x 3 plant
exponentials, 80 x 80 eigen-decompositions); OpenBLAS threads competing with other work on
the machine made them 10-40x slower (measured on this 2-core machine under load, docs/speed.md).
:func:`one_blas_thread` wraps the entry points (library calls included); nested calls pass
straight through, so only the outermost pays for threadpoolctl. Inside an FMU, which carries
this package without threadpoolctl, it changes nothing (the FMUs' steps use no BLAS).
"""
from __future__ import annotations

import functools
import threading

_pinned = threading.local()


@functools.lru_cache(maxsize=1)
def _threadpool_limits():
    """threadpoolctl's ``threadpool_limits``, imported at the first call (importing it takes
    about 90 ms, which an FMU's start would pay), or None where it is missing (an FMU's
    copy of the physics on a host without it: nothing to limit)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return None
    return threadpool_limits


def one_blas_thread(function):
    """Decorate ``function`` to run with BLAS on one thread (once per outermost call)."""
    @functools.wraps(function)
    def pinned(*args, **kwargs):
        threadpool_limits = _threadpool_limits()
        if threadpool_limits is None or getattr(_pinned, "active", False):
            return function(*args, **kwargs)
        _pinned.active = True
        try:
            with threadpool_limits(limits=1, user_api="blas"):
                return function(*args, **kwargs)
        finally:
            _pinned.active = False

    return pinned
