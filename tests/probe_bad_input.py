"""Count how feedaxis treats many malformed inputs (the notes of issues 15 and 26); not a test.

    PYTHONPATH=src python tests/probe_bad_input.py [--n N] [--slow-n M] [CLASS ...]

Draws from the strategies of ``test_fuzz.py`` (and the helpers of ``test_reliability.py``)
and prints, per class, how many were tried and how many came out clean: accepted, or
refused with exit 2 / one :class:`InputError` naming the file (or the parameter), and for
writers nothing half-written. Anything else is "left" (a crash, another exit code,
non-strict JSON, a partial file) and is listed with its kind. ``--n`` draws for the fast
classes, ``--slow-n`` for those that run a fit, a build or a process per draw.
"""
import argparse
import contextlib
import io
import json
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np
import tomli_w
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path[:0] = [str(Path(__file__).parent), str(Path(__file__).parent / "cli")]
from test_fuzz import (BOUNDS, CONTENT, ENCODINGS, FILES, FUZZ, GOOD, GUESSES,  # noqa: E402
                       IMPORT_TEXTS, IMPORT_TIME, RETURNS, TIME_STEPS, _cli_json,
                       _controller_text, _strict, _write, controller_outcome,
                       positioning_cases,
                       toml_with_a_strange_value, within_loop_budget, write_effect_case,
                       write_span_case)

from feedaxis.case import read_case, write_case  # noqa: E402
from feedaxis.comptable import CONTROLLERS  # noqa: E402
from feedaxis.effects import CATALOG, load_model  # noqa: E402
from feedaxis.effects.tracking import TRACKING_EFFECTS  # noqa: E402
from feedaxis.errors import InputError  # noqa: E402

COMMANDS = (["fit", "{case}", "--add", "lead_error", "--add", "backlash"],
            ["compare", "{case}"], ["diagnose", "{case}"])
CLEAN = ("accepted", "refused with location", "interrupted: exit 130, only whole FMUs",
         "disk full: exit 2 naming the file, nothing left")


def located(error, *paths):
    return error.path is not None and str(error.path) in str(error) and any(
        error.path == p or p in error.path.parents for p in paths)


def drawn(strategy, n, check, **extra):
    """Counter of ``check(example)`` over ``n`` draws of ``strategy``."""
    counts = Counter()

    @settings(FUZZ, max_examples=n)
    @given(example=strategy, **extra)
    def probe(example, **more):
        try:
            counts[check(example, **more)] += 1
        except Exception as error:  # noqa: BLE001 - what the probe is looking for
            counts[f"left: {type(error).__name__}: {str(error)[:80]}"] += 1

    probe()
    return counts


def cli_outcome(argv, written=None):
    """accepted / refused with location / left, for ``feedaxis argv --json``."""
    code, out, _ = _cli_json([*map(str, argv), "--json"])
    payload = _strict(out)
    if code == 0:
        return "accepted"
    if code == 2 and (payload.get("file") or payload.get("parameter")):
        return "left: written although refused" if written and written.exists() else \
            "refused with location"
    return f"left: exit {code}: {payload.get('error', '')[:80]}"


def reader(root, n):
    def check(example, name):
        folder = Path(tempfile.mkdtemp(dir=root)) / "c"
        _write(folder, dict(GOOD, **{name: example}))
        try:
            read_case(folder)
            return "accepted"
        except InputError as error:
            return "refused with location" if located(error, folder) else "left: unlocated"
    return drawn(CONTENT, n, check, name=st.sampled_from(FILES))


def cli(root, n, command):
    def check(columns):
        folder = Path(tempfile.mkdtemp(dir=root)) / "c"
        write_case(folder, {"name": "probe", "screw": {"lead_mm": 5.0}},
                   positioning={k: np.asarray(v, dtype=float) for k, v in columns.items()})
        return cli_outcome([p.format(case=folder) for p in command])
    return drawn(positioning_cases(), n, check)


def toml(root, n):
    def check(text, as_model):
        folder = Path(tempfile.mkdtemp(dir=root))
        _write(folder / "c", dict(GOOD, **({} if as_model else {"axis.toml": text})))
        (folder / "m.toml").write_text(text)
        try:
            load_model(folder / "m.toml", CATALOG) if as_model else read_case(folder / "c")
            return "accepted"
        except InputError as error:
            return ("refused with location" if located(error, folder / "m.toml", folder / "c")
                    else "left: unlocated")
    return drawn(toml_with_a_strange_value(), n, check, as_model=st.booleans())


def encodings(root, n):
    def check(text, encoding, axis_encoding, suffix):
        folder = Path(tempfile.mkdtemp(dir=root))
        (folder / f"x{suffix}").write_bytes(text.encode(encoding, errors="replace"))
        (folder / "axis.toml").write_bytes("# \xb5\n[screw]\nlead_mm = 5.0\n".encode(
            axis_encoding, errors="replace"))
        return cli_outcome(["import", folder / f"x{suffix}", "--axis", folder / "axis.toml",
                            "--out", folder / "case"], written=folder / "case")
    return drawn(IMPORT_TEXTS, n, check, encoding=ENCODINGS, axis_encoding=ENCODINGS,
                 suffix=st.sampled_from([".csv", ".rtl"]))


def user_effects(root, n):
    def check(body, bounds, guess, extra):
        folder = Path(tempfile.mkdtemp(dir=root))
        return cli_outcome(write_effect_case(folder, bounds, body, guess, extra)[:-1])
    return drawn(RETURNS, n, check, bounds=BOUNDS, guess=GUESSES, extra=IMPORT_TIME)


def controller_tables(root, n):
    def check(data, name):
        module = CONTROLLERS[name]
        outcome = controller_outcome(module, _controller_text(data.draw, module))
        return {"read": "accepted", "refused": "refused with location"}.get(outcome,
                                                                           f"left: {outcome}")
    return drawn(st.data(), n, check, name=st.sampled_from(list(CONTROLLERS)))


def tracking_spans(root, n):
    def check(steps, loop_step_s):
        folder = Path(tempfile.mkdtemp(dir=root)) / "c"
        write_span_case(folder, steps, loop_step_s)
        try:
            case = read_case(folder)
        except InputError as error:
            return "refused with location" if located(error, folder) else "left: unlocated"
        return "accepted" if within_loop_budget(case) else "left: beyond the loop's budget"
    return drawn(st.lists(TIME_STEPS, min_size=1, max_size=40), n, check,
                 loop_step_s=st.sampled_from([1e-4, 1e-7, 1e-2, None]))


def tracking_models(root, n, seed=26):
    """Tracking models with values anywhere within their effects' bounds (both ends, tiny,
    log-uniform) through compare, fit and diagnose of a 1.5 s tracking case."""
    from test_reliability import tracking_case

    rng = random.Random(seed)
    case = tracking_case(Path(tempfile.mkdtemp(dir=root)) / "t", np.arange(0.0, 1.5, 1e-3))
    counts = Counter()
    for _ in range(n):
        effects = [e for e in TRACKING_EFFECTS if rng.random() < 0.6] or [TRACKING_EFFECTS[0]]
        model = {e.name: {p.name: _in_bounds(rng, p) for p in e.parameters} for e in effects}
        path = Path(tempfile.mkdtemp(dir=root)) / "m.toml"
        path.write_text(tomli_w.dumps(model))
        command = rng.choice(["compare", "fit", "diagnose"])
        counts[cli_outcome([command, case, "--model", path])] += 1
    return counts


def _in_bounds(rng, parameter):
    low, high = parameter.lower, parameter.upper
    kind = rng.randrange(5)
    if kind == 0:
        return low
    if kind == 1:
        return high
    if kind == 2:
        return max(low, 10 ** rng.uniform(-300, -100))
    return 10 ** rng.uniform(np.log10(max(low, 1e-12)), np.log10(high))


def interrupted_builds(root, n, seed=26):
    """``build-fmus`` interrupted at a random moment after it began: exit 130 with one line
    (or 0 when it finished first) and only whole FMUs left."""
    from test_reliability import FEEDAXIS, assert_complete_fmus, default_sigint
    from feedaxis.fmu_build import build_fmus

    rng = random.Random(seed)
    reference = {p.stem: p for p in build_fmus(Path(tempfile.mkdtemp(dir=root)))}
    counts = Counter()
    for _ in range(n):
        out = Path(tempfile.mkdtemp(dir=root)) / "fmus"
        build = subprocess.Popen([*FEEDAXIS, "build-fmus", "--out", str(out)],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                 preexec_fn=default_sigint)
        while not out.exists() and build.poll() is None:
            time.sleep(0.01)
        time.sleep(rng.uniform(0.0, 4.0))
        build.send_signal(signal.SIGINT)
        code, err = build.wait(), build.stderr.read()
        try:
            assert_complete_fmus(out, reference)
            whole = not list(out.parent.rglob(".*"))
        except AssertionError:
            whole = False
        clean = (code == 130 and err == "feedaxis: interrupted\n" or code == 0) and whole
        counts["accepted" if clean and code == 0 else CLEAN[2] if clean else
               f"left: exit {code}, whole {whole}: {err[-80:]!r}"] += 1
    return counts


def full_disk(root, n):
    """Each writing command on a 64 kB disk (``n`` rounds of the six)."""
    import pytest
    from test_reliability import on_small_disk
    from test_bad_input import small_case
    from feedaxis.fmu_build import build_fmus

    fmus = Path(tempfile.mkdtemp(dir=root)) / "fmus"
    build_fmus(fmus)
    counts = Counter()
    for _ in range(n):
        folder = Path(tempfile.mkdtemp(dir=root))
        case = small_case(folder / "c")
        (folder / "m.toml").write_text("[lead_error]\noffset_um = 0.1\nslope_um_per_mm = 0\n")
        for argv in (["report", case, "--model", folder / "m.toml", "--out", "DISK/r.html"],
                     ["simulate", "tracking", "DISK/t", "--fmus", fmus, "--duration-s", "3"],
                     ["build-fmus", "--out", "DISK/fmus"], ["export-ssp", "DISK/a.ssp",
                                                            "--fmus", fmus],
                     ["export-fmu", "DISK/a.fmu", "--fmus", fmus], ["demo", "--out", "DISK/d"]):
            place = Path(tempfile.mkdtemp(dir=folder))
            try:
                code, err, left = on_small_disk(place, argv)
            except pytest.skip.Exception as skipped:
                return Counter({f"not run: {skipped}": 1})
            files = [entry for entry in left if not entry.startswith("d ")]
            clean = code == 2 and "no space left on the device" in err and not files
            counts[CLEAN[3] if clean else f"left: {argv[0]} exit {code}, files {files[:2]}"] += 1
    return counts


CLASSES = {
    "reader": (reader, "fast"), "fit": (lambda r, n: cli(r, n, COMMANDS[0]), "slow"),
    "compare": (lambda r, n: cli(r, n, COMMANDS[1]), "slow"),
    "diagnose": (lambda r, n: cli(r, n, COMMANDS[2]), "slow"),
    "toml": (toml, "fast"), "encodings": (encodings, "fast"),
    "user-effects": (user_effects, "slow"), "controller-tables": (controller_tables, "fast"),
    "tracking-spans": (tracking_spans, "fast"), "tracking-models": (tracking_models, "slow"),
    "interrupted-builds": (interrupted_builds, "slow"), "full-disk": (full_disk, "slow"),
}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("classes", nargs="*", metavar="CLASS",
                        help=f"some of {', '.join(CLASSES)} (default: all)")
    parser.add_argument("--n", type=int, default=1000, help="draws per fast class")
    parser.add_argument("--slow-n", type=int, default=50, help="draws per slow class")
    args = parser.parse_args()
    unknown = sorted(set(args.classes) - set(CLASSES))
    if unknown:
        parser.error(f"unknown class {unknown[0]}")
    root = tempfile.mkdtemp(prefix="feedaxis-probe-")
    try:
        for name in args.classes or CLASSES:
            probe, speed = CLASSES[name]
            with contextlib.redirect_stderr(io.StringIO()):
                counts = probe(root, args.n if speed == "fast" else args.slow_n)
            tried, clean = sum(counts.values()), sum(counts[k] for k in CLEAN)
            print(f"{name}: {clean} / {tried} clean {json.dumps(dict(counts))}", flush=True)
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
