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
from .memory import keep_freed_memory


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
