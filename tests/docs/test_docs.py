"""The documentation: the mkdocs site builds with no broken link, and every code block is real.

Every fenced block in README.md and docs/ carries a marker comment on the line above saying
how it is kept true (a block without one fails :func:`test_every_code_block_is_kept_true`):

- ``<!-- snippet: NAME -->``: Python run by a test (here, or tests/docs/test_docs_cosim.py);
- ``<!-- example: examples/FILE -->`` (or a file of ``src/feedaxis/data/``, shipped with the
  package): the block is that file, verbatim;
- ``<!-- transcript -->``: a console session; the ``$`` lines are run in one folder per page
  (holding a copy of ``examples/``) and their output must match the lines below them (a
  ``...`` line stands for any lines, numbers agree to 0.1 %;
  ``$ cat FILE`` shows an input file, which is written as shown);
- ``<!-- commands: tests/FILE.py::TEST -->``: commands with placeholders (CASE, FILE) that the
  named test runs on a real case;
- a ``text`` block is a diagram or a listing, not code; the README's two install commands
  (``pip install ...``) are what the CI itself runs.
"""
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import unavailable

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCK = re.compile(r"(?:<!-- ([^\n]*?) -->\n)?```(\w*)\n(.*?)```", re.S)
SRC = str(ROOT / "src")


def blocks(page):
    """(marker, language, body) of each fenced block of one page."""
    return [(m.group(1) or "", m.group(2), m.group(3))
            for m in BLOCK.finditer(page.read_text(encoding="utf-8"))]


def page_blocks(kind):
    """(page, body) of every block whose marker starts with ``kind``, as pytest params."""
    return [pytest.param(page, marker, body, id=f"{page.name}:{i}")
            for page in PAGES for i, (marker, _, body) in enumerate(blocks(page))
            if marker.startswith(kind)]


def mkdocs_build(config, site):
    """Run ``mkdocs build --strict``; the completed process."""
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict",
                           "-f", str(config), "-d", str(site)],
                          capture_output=True, text=True)


@pytest.fixture
def mkdocs():
    if shutil.which("mkdocs") is None and subprocess.run(
            [sys.executable, "-c", "import mkdocs"], capture_output=True).returncode:
        unavailable("mkdocs is not installed (pip install '.[test]' brings it)")


def test_docs_build_strict(mkdocs, tmp_path):
    done = mkdocs_build(ROOT / "mkdocs.yml", tmp_path / "site")
    assert done.returncode == 0, done.stderr


def test_docs_build_fails_on_a_broken_link(mkdocs, tmp_path):
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    shutil.copy2(ROOT / "mkdocs.yml", tmp_path / "mkdocs.yml")
    with open(tmp_path / "docs" / "speed.md", "a", encoding="utf-8") as page:
        page.write("\nSee [the gone page](gone.md).\n")
    done = mkdocs_build(tmp_path / "mkdocs.yml", tmp_path / "site")
    assert done.returncode != 0 and "gone.md" in done.stderr


def test_every_code_block_is_kept_true():
    loose = [f"{page.relative_to(ROOT)} block {i}: {body[:60]!r}"
             for page in PAGES for i, (marker, language, body) in enumerate(blocks(page))
             if language != "text" and not body.startswith("pip install") and not re.match(
                 r"(snippet: [\w-]+|example: (examples|src/feedaxis/data)/\S+|transcript|"
                 r"commands: tests/\S+::\w+)$",
                 marker)]
    assert not loose, "blocks without a marker:\n" + "\n".join(loose)


@pytest.mark.parametrize("page, marker, body", page_blocks("example:"))
def test_example_block_is_the_file(page, marker, body):
    assert body == (ROOT / marker.split(": ", 1)[1]).read_text(encoding="utf-8")


@pytest.mark.parametrize("page, marker, body", page_blocks("commands:"))
def test_commands_block_names_a_test_that_exists(page, marker, body):
    path, name = marker.split(": ", 1)[1].split("::")
    assert re.search(rf"^def {name}\(", (ROOT / path).read_text(encoding="utf-8"), re.M)


def run_line(command, folder):
    """Run one ``$`` line of a transcript in ``folder``; its stdout lines."""
    env = dict(os.environ, PYTHONPATH=SRC, COLUMNS="100")
    argv = shlex.split(command)
    if argv[0] == "feedaxis":
        argv = [sys.executable, "-m", "feedaxis.cli", *argv[1:]]
    elif argv[0] == "python":
        argv[0] = sys.executable
    done = subprocess.run(argv, cwd=folder, env=env, capture_output=True, text=True)
    assert done.returncode == 0, f"$ {command}\n{done.stderr}"
    return done.stdout.splitlines()


def matches(expected, printed):
    """Whether printed lines match expected ones, a ``...`` line standing for any lines."""
    if not expected:
        return not printed
    if expected[0].strip() == "...":
        return any(matches(expected[1:], printed[i:]) for i in range(len(printed) + 1))
    return bool(printed) and same_line(expected[0], printed[0]) and matches(expected[1:], printed[1:])


NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?")


def same_line(expected, printed):
    """Equal words, numbers equal to 0.1 % (the last digits vary with BLAS and CPU, and the
    column padding with them)."""
    if NUMBER.sub("#", expected).split() != NUMBER.sub("#", printed).split():
        return False
    return all(float(a) == pytest.approx(float(b), rel=1e-3, abs=1e-12)
               for a, b in zip(NUMBER.findall(expected), NUMBER.findall(printed)))


def sessions(body):
    """(command, expected output lines) of each ``$`` line of a transcript."""
    found = []
    for line in body.splitlines():
        if line.startswith("$ "):
            found.append((line[2:], []))
        else:
            found[-1][1].append(line)
    return found


@pytest.mark.parametrize("page", [p for p in PAGES if any(
    m == "transcript" for m, _, _ in blocks(p))], ids=lambda p: p.name)
def test_transcripts_print_what_the_page_shows(page, tmp_path):
    shutil.copytree(ROOT / "examples", tmp_path / "examples")   # run from the project folder
    for marker, _, body in blocks(page):
        if marker != "transcript":
            continue
        for command, expected in sessions(body):
            if command.startswith("cat "):   # an input file the page gives the reader
                (tmp_path / command[4:]).write_text("\n".join(expected) + "\n", encoding="utf-8")
                printed = expected
            else:
                printed = run_line(command, tmp_path)
            assert matches(expected, printed), \
                f"$ {command}\nexpected:\n" + "\n".join(expected) + "\nprinted:\n" + "\n".join(printed)


def commands(page, marker):
    """The commands of the block marked ``marker`` on ``page``, comments dropped."""
    body = next(b for m, _, b in blocks(ROOT / page) if m == marker)
    return [line.split("  #")[0].strip() for line in body.splitlines() if line.strip()]


def test_loop_commands_run_on_the_demo_case(tmp_path):
    from feedaxis.examples import write_seed001_case, write_table2_case
    write_seed001_case(tmp_path / "case")
    write_table2_case(tmp_path / "thermal-case", 9000.0)
    run_line("feedaxis fit thermal-case --add lead_error --add thermal_screw --out thermal.toml",
             tmp_path)
    marker = "commands: tests/docs/test_docs.py::test_loop_commands_run_on_the_demo_case"
    lines = commands("README.md", marker)
    assert lines == commands("docs/loop.md", marker)
    for line in lines:
        run_line(line.replace("THERMAL_CASE", "thermal-case").replace("CASE", "case"), tmp_path)
    assert (tmp_path / "report.html").stat().st_size > 0


def test_comp_table_commands_run_on_an_rtl_export(tmp_path):
    from feedaxis.examples import LASER_EXAMPLE
    for name in ("X-axis.rtl", "axis.toml"):   # the laser example shipped with the package
        shutil.copy2(LASER_EXAMPLE / name, tmp_path / name)
    marker = "commands: tests/docs/test_docs.py::test_comp_table_commands_run_on_an_rtl_export"
    for line in commands("docs/compensation-tables.md", marker):
        run_line(line, tmp_path)
    assert (tmp_path / "X1_EEC.INI").stat().st_size > 0
