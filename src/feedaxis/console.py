"""The ``feedaxis`` console script: Ctrl-C at any moment exits 130 with one line.

It imports next to nothing, so that it is running before the seconds of start-up imports
(NumPy, SciPy) begin: an interrupt during them, as during a command, says ``interrupted``
once instead of a traceback. (Before this module runs, Python's own start-up, its ``site``
import of some 0.05 s, reports an interrupt itself.) The command line itself is
:func:`feedaxis.cli.main`.
"""
from __future__ import annotations

import signal
import sys

INTERRUPTED_EXIT = 130


def run():
    """Run ``feedaxis`` with ``sys.argv`` and exit with its code."""
    try:
        from .cli import main

        code = main()
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C cannot cut the line
        code = fail("--json" in sys.argv[1:], "interrupted", INTERRUPTED_EXIT)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # nor the exit
    sys.exit(code)


def fail(wants_json, message, code, payload=None):
    """Report a failure on stderr, and as JSON on stdout with ``--json``; return ``code``."""
    import json

    print(f"feedaxis: {message}", file=sys.stderr)
    if wants_json:
        print(json.dumps(payload or {"error": message, "file": None, "row": None,
                                     "column": None, "parameter": None}, indent=2, allow_nan=False))
    return code
