"""Count how feedaxis treats many malformed inputs (the note of issue 15); not a test.

    PYTHONPATH=src python tests/probe_bad_input.py [READER_PROBES] [CLI_PROBES]

Draws from the strategies of ``test_fuzz.py``: any bytes in one file of a case (reader), and
valid-format cases with random values through ``fit``, ``compare`` and ``diagnose --json``.
Prints, per kind, how many were accepted, refused with a location (exit 2, the file named),
and anything else ("left": a crash, another exit code, non-strict JSON).
"""
import shutil
import sys
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np
from hypothesis import given, settings

sys.path.insert(0, str(Path(__file__).parent))
from test_fuzz import (CONTENT, FILES, FUZZ, GOOD, _cli_json, _strict,  # noqa: E402
                       _write, positioning_cases)
from hypothesis import strategies as st  # noqa: E402

from feedaxis.case import read_case, write_case  # noqa: E402
from feedaxis.errors import InputError  # noqa: E402

COMMANDS = (["fit", "{case}", "--add", "lead_error", "--add", "backlash"],
            ["compare", "{case}"], ["diagnose", "{case}"])


def probe_reader(root, n):
    counts = Counter()

    @settings(FUZZ, max_examples=n)
    @given(name=st.sampled_from(FILES), data=CONTENT)
    def probe(name, data):
        folder = Path(tempfile.mkdtemp(dir=root)) / "c"
        _write(folder, dict(GOOD, **{name: data}))
        try:
            read_case(folder)
            counts["accepted"] += 1
        except InputError as error:
            named = error.path is not None and str(error.path) in str(error)
            counts["refused with location" if named else "left"] += 1
        except Exception as error:  # noqa: BLE001 - what the probe is looking for
            counts[f"left: {type(error).__name__}"] += 1

    probe()
    return counts


def probe_cli(root, command, n):
    counts = Counter()

    @settings(FUZZ, max_examples=n)
    @given(columns=positioning_cases())
    def probe(columns):
        folder = Path(tempfile.mkdtemp(dir=root)) / "c"
        write_case(folder, {"name": "probe", "screw": {"lead_mm": 5.0}},
                   positioning={k: np.asarray(v, dtype=float) for k, v in columns.items()})
        try:
            code, out, _ = _cli_json([p.format(case=folder) for p in command] + ["--json"])
            payload = _strict(out)
        except Exception as error:  # noqa: BLE001
            counts[f"left: {type(error).__name__}"] += 1
            return
        if code == 0:
            counts["accepted"] += 1
        elif code == 2 and payload.get("file"):
            counts["refused with location"] += 1
        else:
            counts[f"left: exit {code}"] += 1

    probe()
    return counts


def main():
    reader_n = int(sys.argv[1]) if len(sys.argv) > 1 else 4000
    cli_n = int(sys.argv[2]) if len(sys.argv) > 2 else 200
    root = tempfile.mkdtemp(prefix="feedaxis-probe-")
    try:
        print(f"reader, {reader_n} drawn: {dict(probe_reader(root, reader_n))}")
        for command in COMMANDS:
            print(f"{command[0]}, {cli_n} drawn: {dict(probe_cli(root, command, cli_n))}")
    finally:
        shutil.rmtree(root)


if __name__ == "__main__":
    main()
