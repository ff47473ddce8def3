"""The ``feedaxis`` console script and ``python -m feedaxis``: Ctrl-C at any moment exits
130 with one line, SIGTERM 143 and SIGHUP 129 the same way (:mod:`feedaxis.stop`).

It imports next to nothing, so that it is running before the seconds of start-up imports
(NumPy, SciPy) begin: an interrupt during them, as during a command, says ``interrupted``
once instead of a traceback. (Before this module runs, Python's own start-up, its ``site``
import of some 0.05 s, reports an interrupt itself.) The command line itself is
:func:`feedaxis.cli.main`.
"""
import sys

from . import stop
from .console import fail


M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters (malloc.h)
KEPT_BLOCK_BYTES = 1 << 30  # freed memory up to this much stays in the heap for reuse (a C int)
MAPPED_BLOCK_BYTES = 1 << 25  # a block this large (32 MB) is mapped on its own, unmapped when freed


def keep_freed_memory():
    """Let glibc's malloc keep freed blocks below ``MAPPED_BLOCK_BYTES`` in its heap for
    reuse instead of unmapping them: the analysis allocates and frees sample-sized arrays
    hundreds of times, and every fresh mapping is faulted in page by page (diagnose on
    10^6 rows spent 1.5 of its 5 CPU seconds in the kernel so). Larger blocks (a
    sample-sized array from 4·10^6 samples on) are still mapped on their own: reused in
    the heap, the holes between them held up to 300 MB more than the live arrays at
    10^7 rows (peak resident memory 2.3 GB where 1.8 GB was allocated), at 10 ms of the
    kernel's for each (diagnose on 10^7 rows: 4 -> 13 s). Nothing changes off glibc."""
    import ctypes

    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt(M_MMAP_THRESHOLD, MAPPED_BLOCK_BYTES)
    mallopt(M_TRIM_THRESHOLD, KEPT_BLOCK_BYTES)


def run():
    """Run ``feedaxis`` with ``sys.argv`` and exit with its code."""
    stop.install()
    keep_freed_memory()
    try:
        from .cli import main

        code = main()
    except Exception as error:  # an interrupt an extension's import turned into an error
        if stop.interrupt_behind(error) is None:
            raise
        code = _interrupted()
    except KeyboardInterrupt:
        code = _interrupted()
    stop.ignore_all()  # nor the exit
    stop.leave(code)


def _interrupted():
    """The stop's exit code, after its one line."""
    stop.ignore_all()  # a second signal cannot cut the line
    return fail("--json" in sys.argv[1:], stop.described("interrupted"), stop.exit_code())


if __name__ == "__main__":
    run()
