"""Property-based fuzzing of the case reader and the CLI (issue 15), about a minute in all.

- any bytes in any case file: a :class:`Case` or one :class:`InputError` naming a file of
  the case (never another exception);
- valid-format cases with random values (positioning, and positioning with tracking
  beside) through ``fit``, ``compare`` and ``diagnose``: exit 0 or 2, stdout strict JSON,
  traced memory bounded.
"""
import contextlib
from collections import Counter
import io
import json
import os
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from feedaxis.case import read_case, write_case
from feedaxis.cli import main
from feedaxis.errors import InputError

FILES = ("axis.toml", "positioning.csv", "duty.csv", "tracking.csv")
GOOD = {
    "axis.toml": "name = 'fuzz'\n[screw]\nlead_mm = 5.0\nlength_m = 0.8\n",
    "positioning.csv": "target_mm,error_um,direction,run,time_s\n0,1.5,+1,1,0\n100,2.5,-1,1,50\n",
    "duty.csv": "start_s,duration_s,feed_mm_min,from_mm,to_mm\n0,60,1000,0,100\n",
    "tracking.csv": "time_s,reference_mm,actual_mm\n0,0,0\n0.001,0.1,0.09\n",
}
MEMORY_LIMIT_BYTES = 300e6
# CI explores one fixed sample (a failure there is reproducible); elsewhere every run
# draws anew, which is how the finds in test_bad_input.py were made.
FUZZ = settings(deadline=None, database=None, derandomize=os.environ.get("CI") == "true",
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

# Text made of the format's own tokens, so the fuzzer gets past the header often.
TOKENS = st.sampled_from(["target_mm", "error_um", "direction", "run", "time_s", "ambient_C",
                          "start_s", "duration_s", "feed_mm_min", "from_mm", "to_mm",
                          "time_s", "reference_mm", "actual_mm", ",", "\n", "\r\n", "#", " ",
                          "+1", "-1", "0", "1", "2.5", "-3e2", "1e200", "nan", "inf", "x",
                          "[screw]", "[motor]", "lead_mm = ", "length_m = ", "name = ", "'a'",
                          "\ufeff", "\xb5", "\x00", '"', "="])
CONTENT = st.one_of(
    st.binary(max_size=300),
    st.lists(TOKENS, max_size=60).map(lambda parts: "".join(parts).encode("utf-8")),
    st.tuples(st.lists(TOKENS, max_size=40), st.sampled_from(["latin-1", "utf-16", "utf-8-sig",
                                                              "cp1252"]))
    .map(lambda pair: "".join(pair[0]).encode(pair[1], errors="replace")),
)


def _write(folder, files):
    folder.mkdir()
    for name, data in files.items():
        (folder / name).write_bytes(data if isinstance(data, bytes) else data.encode())


@settings(FUZZ, max_examples=1500)
@given(name=st.sampled_from(FILES), data=CONTENT, as_folder=st.booleans())
def test_any_bytes_in_a_case_file_give_a_case_or_one_input_error(tmp_path_factory, name, data,
                                                                 as_folder):
    folder = tmp_path_factory.mktemp("case") / "c"
    files = dict(GOOD, **{name: data})
    if as_folder and name != "axis.toml":
        del files[name]
    _write(folder, files)
    if as_folder and name != "axis.toml":
        (folder / name).mkdir()
    try:
        case = read_case(folder)
    except InputError as error:
        event("refused naming the file")
        assert error.path is not None and (error.path == folder or error.path.parent == folder)
        assert str(error.path) in str(error)
    else:
        event("accepted")
        assert case.positioning is not None or case.tracking is not None


FINITE = st.floats(allow_nan=False, allow_infinity=False, width=64)
VALUES = st.one_of(st.floats(-2e3, 2e3), st.integers(-5, 5).map(float),
                   st.sampled_from([0.0, 1e-12, -1e-300, 5e-324]))


@st.composite
def positioning_cases(draw):
    """Valid-format positioning.csv columns with random values (sizes 1-60); in about half
    of them one value anywhere in the float range."""
    n = draw(st.integers(1, 60))
    columns = {"target_mm": draw(st.lists(VALUES, min_size=n, max_size=n)),
               "error_um": draw(st.lists(VALUES, min_size=n, max_size=n))}
    if draw(st.booleans()):
        columns["direction"] = draw(st.lists(st.sampled_from([-1, 1]), min_size=n, max_size=n))
        columns["run"] = draw(st.lists(st.integers(1, 5), min_size=n, max_size=n))
    if draw(st.booleans()):
        column = draw(st.sampled_from(["target_mm", "error_um"]))
        columns[column][draw(st.integers(0, n - 1))] = draw(FINITE)
    return columns


SERVO = {"controller": "pid", "kp_V_per_mm": 0.9, "ki_V_per_mm_s": 6e-4, "kd_V_s_per_mm": 5e-3,
         "force_constant_N_per_V": 100.0}


@st.composite
def tracking_columns(draw):
    """Valid-format tracking.csv columns (sizes 2-60, steps 0.1-10 ms) with random values."""
    n = draw(st.integers(2, 60))
    steps = draw(st.lists(st.floats(1e-4, 1e-2), min_size=n - 1, max_size=n - 1))
    reference = draw(st.lists(st.floats(-50, 50), min_size=n, max_size=n))
    offsets = draw(st.lists(st.one_of(st.floats(-1, 1), VALUES), min_size=n, max_size=n))
    return {"time_s": np.concatenate(([0.0], np.cumsum(steps))),
            "reference_mm": np.asarray(reference),
            "actual_mm": np.clip(np.asarray(reference) + np.asarray(offsets) * 1e-3, -1e5, 1e5)}


def _cli_json(argv):
    """Exit code and stdout of ``feedaxis argv`` (stderr swallowed) and traced peak bytes."""
    out, err = io.StringIO(), io.StringIO()
    tracemalloc.start()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return code, out.getvalue(), peak


def _strict(text):
    def refuse(constant):
        raise AssertionError(f"non-strict JSON constant {constant}")
    return json.loads(text, parse_constant=refuse)


@pytest.mark.parametrize("command, examples", [
    (["fit", "{case}", "--add", "lead_error", "--add", "backlash"], 150),
    (["fit", "{case}", "--add", "coulomb_friction"], 40),
    (["compare", "{case}"], 150),
    (["diagnose", "{case}"], 60),
])
def test_cli_on_random_values_exits_0_or_2_with_strict_json(tmp_path_factory, command,
                                                            examples):
    """Positioning cases, and in about half of them a tracking.csv beside (a case holding
    both measurements) with the [servo] table."""
    exits = Counter()

    @settings(FUZZ, max_examples=examples)
    @given(columns=positioning_cases(), lead_mm=st.sampled_from([1.0, 5.0, 1e-3, 1e3]),
           tracking=st.one_of(st.none(), tracking_columns()))
    def check(columns, lead_mm, tracking):
        folder = Path(tmp_path_factory.mktemp("cli")) / "c"
        axis = {"name": "fuzz", "screw": {"lead_mm": lead_mm}}
        if tracking is not None:
            axis["servo"] = SERVO
        write_case(folder, axis, tracking=tracking,
                   positioning={k: np.asarray(v, dtype=float) for k, v in columns.items()})
        argv = [part.format(case=folder) for part in command] + ["--json"]
        code, out, peak = _cli_json(argv)
        exits[code] += 1
        assert code in (0, 2), out
        payload = _strict(out)
        if code == 2:
            assert payload["error"] and payload["file"]
        assert peak < MEMORY_LIMIT_BYTES

    check()
    print(f"{command[0]}: exit codes {dict(exits)}")  # the counts for the notes (pytest -s)
