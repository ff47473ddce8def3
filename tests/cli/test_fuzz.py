"""Property-based fuzzing of the readers and the CLI (issues 15 and 26).

- any bytes in any case file: a :class:`Case` or one :class:`InputError` naming a file of
  the case (never another exception);
- valid-format cases with random values (positioning, and positioning with tracking
  beside) through ``fit``, ``compare`` and ``diagnose``: exit 0 or 2, stdout strict JSON,
  traced memory bounded;
- issue 26's classes: TOML nested deep or holding huge integers (axis.toml, model files);
  every encoding through ``import`` (a readable case or nothing written); user effects
  breaking their contract; controller tables asking for more than they hold; tracking
  spans beyond the control loop's budget. Each draws in bounded time.
"""
import contextlib
import re
from collections import Counter
import io
import json
import os
import tracemalloc
import zipfile
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


# --- issue 26: the classes of bad input found since, each drawn in bounded time ---------

def _located(error, *paths):
    """An InputError naming one of ``paths`` (or inside one of them) in its message."""
    return (isinstance(error, InputError) and error.path is not None
            and any(error.path == p or p in error.path.parents for p in paths)
            and str(error.path) in str(error))


def _nested(kind, depth):
    return ("[" * depth + "1" + "]" * depth) if kind == "array" else (
        "{a = " * depth + "1" + "}" * depth)


TOML_VALUES = st.one_of(
    st.builds(_nested, st.sampled_from(["array", "table"]), st.integers(1, 400)),
    st.builds(lambda sign, n: sign + "1" + "0" * (n - 1), st.sampled_from(["", "-", "+"]),
              st.integers(1, 6000)),
    st.integers(1, 6000).map(lambda n: "1_" + "0" * n),
    st.sampled_from(["1e400", "-1e400", "inf", "nan", "0", "-5", "5.0", "1e-320", "true",
                     "'x'", "2026-02-30", "1" + "0" * 308, "1" + "0" * 309]),
)
TOML_KEYS = st.sampled_from(["lead_mm", "length_m", "error_period_steps", "kp_V_per_mm",
                             "x", "offset_um", "slope_um_per_mm"])


@st.composite
def toml_with_a_strange_value(draw):
    """A TOML text: a known table, and a key holding a deep, huge or odd value."""
    table = draw(st.sampled_from(["screw", "motor", "servo", "lead_error"]))
    return (f"[{table}]\n{draw(TOML_KEYS)} = {draw(TOML_VALUES)}\n"
            + draw(st.sampled_from(["", "lead_mm = 5.0\n", "slope_um_per_mm = 0\n"])))


@settings(FUZZ, max_examples=300)
@given(text=toml_with_a_strange_value(), as_model=st.booleans())
def test_deep_or_huge_toml_gives_a_result_or_one_error_naming_the_file(tmp_path_factory, text,
                                                                       as_model):
    from feedaxis.effects import CATALOG, load_model

    folder = tmp_path_factory.mktemp("toml")
    case = folder / "c"
    _write(case, dict(GOOD, **({} if as_model else {"axis.toml": text})))
    path = folder / "m.toml"
    path.write_text(text)
    try:
        load_model(path, CATALOG) if as_model else read_case(case)
        event("accepted")
    except InputError as error:
        event("refused naming the file")
        assert _located(error, path if as_model else case), str(error)


ENCODINGS = st.sampled_from(["utf-8", "utf-8-sig", "utf-16", "utf-16-le", "latin-1", "cp1252"])
IMPORT_TEXTS = st.one_of(
    st.just("target_mm,run1+,run1-\n# Lauf \xb5m\n0,1.0,2.0\n50,1.5,2.5\n"),
    st.just("target_mm;run1+;run1-\n0;1,0;2,0\n50;1,5;2,5\n"),
    st.lists(st.sampled_from(["target_mm", "run1+", "run2-", "run1_up", ",", ";", "\n",
                              "\r\n", "0", "50", "1.5", "1e300", "", "#", "\xb5", "\u2028",
                              "nan", "1" + "0" * 5000]), max_size=40).map("".join),
)


@settings(FUZZ, max_examples=80)
@given(text=IMPORT_TEXTS, encoding=ENCODINGS, axis_encoding=ENCODINGS,
       suffix=st.sampled_from([".csv", ".rtl"]))
def test_import_in_any_encoding_writes_a_readable_case_or_nothing(tmp_path_factory, text,
                                                                  encoding, axis_encoding,
                                                                  suffix):
    from feedaxis.importers.rtl import rtl_text

    folder = tmp_path_factory.mktemp("import")
    if suffix == ".rtl":
        text = rtl_text([0.0, 50.0], [(1.0, [1.0, 1.5]), (-1.0, [2.0, 2.5])],
                        {"Machine": "M\xfchle"}) if "run1+" in text else text
    source, axis = folder / f"x{suffix}", folder / "axis.toml"
    source.write_bytes(text.encode(encoding, errors="replace"))
    axis.write_bytes("# Achse \xb5\n[screw]\nlead_mm = 5.0\n".encode(axis_encoding,
                                                                    errors="replace"))
    code, out, _ = _cli_json(["import", str(source), "--axis", str(axis), "--out",
                              str(folder / "case"), "--json"])
    payload = _strict(out)
    assert code in (0, 2), payload
    if code == 0:
        event("imported")
        assert read_case(folder / "case").positioning.size == payload["samples"]
    else:
        event("refused")
        assert payload["file"] and not (folder / "case").exists()
        assert sorted(p.name for p in folder.iterdir()) == sorted(["axis.toml", source.name])


BOUNDS = st.sampled_from(["-10, 10", "5, 5", "5, -5", "-np.inf, 5", "0, np.nan", "-1e308, 1e308",
                          "'a', 'b'", "0, 10**400"])
RETURNS = st.sampled_from(["a_um + 0 * case.positioning.target_mm", "1e300 + 0 * a_um",
                           "np.full(case.positioning.size, 1e300)",
                           "(1 + 1j) * np.ones(case.positioning.size)",
                           "np.full(case.positioning.size, np.nan)", "np.zeros(3)", "None",
                           "'text'", "[a_um] * case.positioning.size",
                           "np.ones(case.positioning.size, dtype=object)",
                           "__import__('sys').exit(5)", "1 / 0",
                           "print('x') or a_um * np.ones(case.positioning.size)"])
GUESSES = st.sampled_from([None, "{'a_um': 1.0}", "{'b_um': 1.0}", "{}", "[1.0]",
                           "{'a_um': float('nan')}", "{'a_um': 1j}", "{'a_um': np.float32(2)}"])
IMPORT_TIME = st.sampled_from(["", "print('hello')\n", "import sys\nsys.exit(2)\n",
                               "raise RuntimeError('x')\n", "while False: pass\n"])


def write_effect_case(folder, bounds, body, guess, extra):
    """A 30-sample case ``folder/c`` and an effects file ``folder/mine.py`` of one effect
    ``probe`` built from the pieces; returns the ``fit`` command line."""
    write_case(folder / "c", {"name": "fuzz", "screw": {"lead_mm": 5.0}},
               positioning={"target_mm": np.linspace(0.0, 100.0, 30),
                            "error_um": np.linspace(0.0, 3.0, 30)})
    guess_code = f", guess=lambda case, residual: {guess}" if guess else ""
    (folder / "mine.py").write_text(
        "import numpy as np\nfrom feedaxis.effects import Parameter, effect\n" + extra +
        f"@effect('probe', 'a probe', [Parameter('a_um', 'um', {bounds})]{guess_code})\n"
        f"def probe(case, a_um):\n    return {body}\n")
    return ["fit", str(folder / "c"), "--effects", str(folder / "mine.py"), "--add", "probe",
            "--json"]


@settings(FUZZ, max_examples=60)
@given(bounds=BOUNDS, body=RETURNS, guess=GUESSES, extra=IMPORT_TIME)
def test_user_effects_exit_0_or_2_with_strict_json(tmp_path_factory, bounds, body, guess,
                                                   extra):
    folder = tmp_path_factory.mktemp("effect")
    code, out, _ = _cli_json(write_effect_case(folder, bounds, body, guess, extra))
    payload = _strict(out)
    assert code in (0, 2), payload
    event("fitted" if code == 0 else "refused")
    if code == 2:
        assert payload["file"] == str(folder / "mine.py"), payload


def _controller_text(draw, module):
    """A file of ``module``'s format: its own output for a small table with one value or
    line replaced by an extreme one, or lines of its tokens."""
    from feedaxis.comptable.table import CompTable

    position_mm = np.arange(0.0, 50.0, 10.0)
    table = CompTable(position_mm, 0.1 * position_mm, 0.1 * position_mm + 2.0, "model")
    lines = module.write(table, module.default_axis_id).splitlines()
    extreme = draw(st.sampled_from(["2147483648", "1e-9", "-1e9", "1e400", "nan", "0", "-1",
                                    "9" * 5000, "1023", "1024", ""]))
    index = draw(st.integers(0, len(lines) - 1))
    lines[index] = re.sub(r"[-+]?\d+(\.\d+)?(e[-+]?\d+)?$", extreme, lines[index])
    if draw(st.booleans()):
        lines = draw(st.permutations(lines))
    return "\n".join(lines) + "\n"


def controller_outcome(module, text):
    """"read" (no more points than the file holds), "refused" (naming the line or field),
    or what is wrong."""
    try:
        table = module.read(text)
    except InputError as error:
        return "refused" if ("line" in str(error) or "field" in str(error)) else \
            f"unlocated: {error}"
    return "read" if table.size <= text.count("\n") + 1024 else "unbounded"


@settings(FUZZ, max_examples=300)
@given(data=st.data(), name=st.sampled_from(["linuxcnc", "siemens", "fanuc", "heidenhain",
                                              "beckhoff", "mach4"]))
def test_controller_tables_read_bounded_or_refused_naming_the_line(data, name):
    from feedaxis.comptable import CONTROLLERS

    module = CONTROLLERS[name]
    outcome = controller_outcome(module, _controller_text(data.draw, module))
    event(outcome)
    assert outcome in ("read", "refused"), outcome


TIME_STEPS = st.one_of(st.floats(1e-5, 1e-2), st.floats(1e-2, 1e9), st.sampled_from([0.0, -1.0]))


def write_span_case(folder, steps, loop_step_s):
    """A tracking case at ``folder`` sampled after the intervals ``steps`` (s), its loop
    stepping ``loop_step_s`` (the default 0.1 ms when None: no [servo] table)."""
    time_s = np.concatenate(([0.0], np.cumsum(steps)))
    servo = "" if loop_step_s is None else (
        '[servo]\ncontroller = "pid"\nkp_V_per_mm = 0.9\nki_V_per_mm_s = 0.0\n'
        f"kd_V_s_per_mm = 0.0\nforce_constant_N_per_V = 100.0\nloop_step_s = {loop_step_s!r}\n")
    rows = "".join(f"{t!r},0.0,0.0\n" for t in time_s.tolist())
    _write(folder, {"axis.toml": "[screw]\nlead_mm = 5.0\n" + servo,
                    "tracking.csv": "time_s,reference_mm,actual_mm\n" + rows})


def within_loop_budget(case):
    """Whether the loop's steps through ``case``'s tracking record stay within its budget."""
    from feedaxis.physics.servo import MAX_INTERVAL_STEPS, MAX_LOOP_STEPS, step_counts

    counts = step_counts(case.tracking.time_s, case.axis.servo.get("loop_step_s", 1e-4))
    return counts.max() <= MAX_INTERVAL_STEPS + 1 and counts.sum() <= MAX_LOOP_STEPS + 1


@settings(FUZZ, max_examples=300)
@given(steps=st.lists(TIME_STEPS, min_size=1, max_size=40),
       loop_step_s=st.sampled_from([1e-4, 1e-7, 1e-2, None]))
def test_tracking_spans_are_read_within_the_loops_budget_or_refused(tmp_path_factory, steps,
                                                                    loop_step_s):
    folder = tmp_path_factory.mktemp("span") / "c"
    write_span_case(folder, steps, loop_step_s)
    try:
        case = read_case(folder)
    except InputError as error:
        event("refused")
        assert _located(error, folder), str(error)
        return
    event("accepted")
    assert within_loop_budget(case)


# --- issue 36: stop signals, outputs aliasing inputs, links out of a case, damaged files ---

SIGTERM_WRITERS = {  # a writing command on the bundled case -> the files it may write
    "fit": (["fit", "{case}", "--add", "lead_error", "--out", "{out}/m.toml"], ["m.toml"]),
    "report": (["report", "{case}", "--out", "{out}/r.html"], ["r.html"]),
    "comp-table": (["comp-table", "{case}", "--controller", "mach4", "--from-measurement",
                    "--out", "{out}/t.txt"], ["t.txt"]),
    "uncertainty": (["uncertainty", "{case}", "--trials", "20000", "--html", "{out}/u.html"],
                    ["u.html"]),
    "simulate": (["simulate", "iso230", "{out}/sim", "--targets", "3", "--runs", "2",
                  "--fmus", "{fmus}"], ["sim"]),
    "import": (["import", "{laser}/X-axis.rtl", "--axis", "{laser}/axis.toml", "--out",
                "{out}/imported"], ["imported"]),
    "export-ssp": (["export-ssp", "{out}/axis.ssp", "--fmus", "{fmus}"], ["axis.ssp"]),
}


def _whole(path):
    """Raise unless ``path``, written by a command, reads back whole with its reader."""
    from feedaxis.comptable import mach4
    from feedaxis.effects import CATALOG, load_model

    if path.suffix == ".toml":
        load_model(path, CATALOG)
    elif path.suffix == ".html":
        assert path.read_text(encoding="utf-8").rstrip().endswith("</html>"), path
    elif path.suffix == ".txt":
        mach4.read(path.read_text(encoding="utf-8"), str(path))
    elif path.suffix == ".ssp":
        with zipfile.ZipFile(path) as archive:
            assert archive.testzip() is None and "SystemStructure.ssd" in archive.namelist()
    else:
        read_case(path)


@pytest.mark.parametrize("command", sorted(SIGTERM_WRITERS))
def test_sigterm_at_a_random_moment_leaves_whole_outputs_or_none(tmp_path, fmu_paths,
                                                                  command):
    """SIGTERM (a scheduler's, ``timeout``'s) at a moment drawn from 0.2 to 5 s into each
    writing command (demo, build-fmus and sweep: test_reliability_two.py), start-up included: exit 143 with one line (or 0 when it finished first), every
    output whole or absent, no staging file or folder left. CI draws a fixed moment."""
    import subprocess
    import signal
    import sys
    import time
    import zlib

    from feedaxis.examples import LASER_EXAMPLE, write_seed001_case

    case, out = write_seed001_case(tmp_path / "case"), tmp_path / "out"
    out.mkdir()
    argv, written = SIGTERM_WRITERS[command]
    argv = [a.format(case=case, out=out, fmus=next(iter(fmu_paths.values())).parent,
                     laser=LASER_EXAMPLE) for a in argv]
    seed = zlib.crc32(command.encode()) if os.environ.get("CI") == "true" else None
    delay_s = np.random.default_rng(seed).uniform(0.2, 5.0)
    process = subprocess.Popen([sys.executable, "-m", "feedaxis", *argv], cwd=tmp_path,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(delay_s)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=300)
    said = [line for line in err.splitlines() if line.startswith("feedaxis:")]
    assert process.returncode in (0, 143), (delay_s, err)
    if process.returncode == 143:
        assert len(said) == 1 and said[0].endswith("(SIGTERM)"), (delay_s, err)
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [], delay_s
    for name in written:
        if (out / name).exists():
            _whole(out / name)
        else:
            assert process.returncode == 143, (delay_s, name)


ALIASED_COMMANDS = (["fit", "{case}", "--add", "lead_error", "--out", "{alias}"],
                    ["report", "{case}", "--out", "{alias}"],
                    ["comp-table", "{case}", "--controller", "mach4", "--from-measurement",
                     "--out", "{alias}"],
                    ["uncertainty", "{case}", "--trials", "1000", "--html", "{alias}"],
                    ["compensate", "{case}", "--model", "{case}/axis.toml", "--out",
                     "{alias}"])


@settings(FUZZ, max_examples=40)
@given(command=st.sampled_from(ALIASED_COMMANDS),
       victim=st.sampled_from(["axis.toml", "positioning.csv"]),
       form=st.sampled_from(["plain", "dotted", "absolute", "symlink", "hard link"]))
def test_an_out_that_is_an_input_in_any_spelling_is_refused(tmp_path_factory, command,
                                                            victim, form):
    """Whatever way the output names an input (relative, through ``..``, absolute, a
    symbolic or a hard link): exit 2 before any work, every case file as it was."""
    root = tmp_path_factory.mktemp("alias")
    folder = root / "c"
    write_case(folder, {"name": "a", "screw": {"lead_mm": 5.0}},
               positioning={"target_mm": np.array([0.0, 50.0, 100.0] * 2),
                            "error_um": np.array([0.1, 0.4, 0.2, 0.2, 0.5, 0.1])})
    alias = {"plain": folder / victim, "dotted": folder / ".." / "c" / "." / victim,
             "absolute": (folder / victim).resolve(), "symlink": root / "link",
             "hard link": root / "hard"}[form]
    if form == "symlink":
        alias.symlink_to(folder / victim)
    elif form == "hard link":
        os.link(folder / victim, alias)
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main([a.format(case=folder, alias=alias) for a in command])
    assert code == 2 and "an input of this command" in err.getvalue(), err.getvalue()
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


@settings(FUZZ, max_examples=60)
@given(links=st.dictionaries(st.sampled_from(["axis.toml", "positioning.csv"]),
                             st.sampled_from(["outside", "outside relative", "inside"]),
                             min_size=1))
def test_case_files_linking_out_of_the_case_are_refused_without_reading_them(
        tmp_path_factory, links):
    """A link leaving the case folder (absolute or ``../``): refused naming the link, the
    target's content never in the message; a link within the case is read."""
    from feedaxis.case import FOLLOW_LINKS

    root = tmp_path_factory.mktemp("links")
    folder, elsewhere = root / "c", root / "elsewhere"
    folder.mkdir()
    elsewhere.mkdir()
    for name in FILES[:2]:
        content = GOOD[name] + "# SECRET-TOKEN\n"
        (elsewhere / name).write_text(content)
        if name not in links:
            (folder / name).write_text(GOOD[name])
        elif links[name] == "inside":
            (folder / f"real-{name}").write_text(GOOD[name])
            (folder / name).symlink_to(f"real-{name}")
        else:
            (folder / name).symlink_to(elsewhere / name if links[name] == "outside"
                                       else Path("..") / "elsewhere" / name)
    outside = [name for name, kind in links.items() if kind != "inside"]
    if outside:
        with pytest.raises(InputError) as refused:
            read_case(folder)
        assert "outside the case folder" in str(refused.value)
        assert refused.value.path.name in outside and "SECRET" not in str(refused.value)
        token = FOLLOW_LINKS.set(True)
        try:
            read_case(folder)
        finally:
            FOLLOW_LINKS.reset(token)
    else:
        read_case(folder)


DAMAGE = st.tuples(st.sampled_from(["truncate", "flip", "empty", "append"]),
                   st.floats(0.0, 1.0))


def _damaged(data, damage):
    kind, where = damage
    at = min(int(where * len(data)), len(data) - 1)
    if kind == "truncate":
        return data[:at]
    if kind == "flip":
        return data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1:]
    return b"" if kind == "empty" else data + bytes(range(256)) * 4


@settings(FUZZ, max_examples=30)
@given(name=st.sampled_from(["GeometricError", "StepperError", "NpidServo", "ThermalScrew"]),
       damage=DAMAGE)
def test_a_damaged_cache_fmu_is_found_or_still_loads(tmp_path_factory, fmu_paths, name,
                                                     damage):
    """A cache entry damaged anywhere is found (and rebuilt: the cache's ``_complete``), or
    is an FMU that still unpacks and loads whole (bytes appended after the archive)."""
    from feedaxis.cosim.fmu_interface import intact
    from feedaxis.cosim.fmu_runner import LoadedFmu

    folder = tmp_path_factory.mktemp("cache")
    paths = {}
    for fmu, path in fmu_paths.items():
        paths[fmu] = folder / path.name
        data = path.read_bytes()
        paths[fmu].write_bytes(_damaged(data, damage) if fmu == name else data)
    if intact(paths):
        event("still an FMU")
        loaded = LoadedFmu(paths[name])
        try:
            loaded.instantiate("probe").freeInstance()
        finally:
            loaded.close()
    else:
        event("rebuilt")


@settings(FUZZ, max_examples=40)
@given(damage=DAMAGE, file=st.sampled_from(["part", "plan"]))
def test_a_damaged_partial_sweep_file_is_refused_naming_it_or_read_whole(tmp_path_factory,
                                                                          damage, file):
    """``sweep --resume`` over a damaged ``.partial`` file: the file named (exit 2), or
    the trials it holds read back as they were saved."""
    from feedaxis.cosim.sweep.store import Store, TrialResult

    out = tmp_path_factory.mktemp("sweep") / "out"
    identity = {"scenario": "iso230", "seed": 0}
    store = Store(out, identity, resume=False)
    saved = [TrialResult(k, (("E_um", 1.5 * k),), np.arange(3.0) + k, None) for k in range(4)]
    store.add(saved, {"x": [0, 1, 2]})
    store.flush()
    path = (next((out / ".partial").glob("part-*.parquet")) if file == "part"
            else out / ".partial" / "plan.json")
    path.write_bytes(_damaged(path.read_bytes(), damage))
    try:
        loaded = Store(out, identity, resume=True).load()
    except InputError as error:
        event("refused")
        assert error.path == path or path.name in str(error), str(error)
        return
    event("read")
    assert sorted(loaded.results) == [r.trial for r in saved]
    for result in saved:
        assert loaded.results[result.trial].figures == result.figures


def test_a_part_file_with_any_one_byte_changed_is_refused_naming_it(tmp_path):
    """Every single-byte change of a saved part file is refused on resume (exit 2 naming
    it), including changes Parquet would read as other values (its name's digest)."""
    from feedaxis.cosim.sweep.store import Store, TrialResult

    out = tmp_path / "out"
    identity = {"scenario": "iso230", "seed": 0}
    store = Store(out, identity, resume=False)
    store.add([TrialResult(k, (("E_um", 1.5 * k),), np.arange(3.0) + k, None)
               for k in range(4)], {"x": [0, 1, 2]})
    store.flush()
    path = next((out / ".partial").glob("part-*.parquet"))
    data = path.read_bytes()
    for at in range(len(data)):
        path.write_bytes(data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1:])
        with pytest.raises(InputError) as refused:
            Store(out, identity, resume=True).load()
        assert refused.value.path == path, at
