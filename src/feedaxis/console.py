"""How the command line reports a failure: one line on stderr, and a JSON object on stdout
with ``--json``. Standard library only, so the console script (:mod:`feedaxis.__main__`)
can report a Ctrl-C before the seconds of start-up imports are over."""
from __future__ import annotations

import sys


def fail(wants_json, message, code, payload=None):
    """Report a failure on stderr, and as JSON on stdout with ``--json``; return ``code``."""
    import json

    print(f"feedaxis: {message}", file=sys.stderr)
    if wants_json:
        print(json.dumps(payload or {"error": message, "file": None, "row": None,
                                     "column": None, "parameter": None}, indent=2,
                         allow_nan=False))
    return code
