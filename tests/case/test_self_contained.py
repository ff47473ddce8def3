"""The repository stands on its own: every link in README, docs and the FMU READMEs, and
every page a ``--help`` names, is a file of the repository; nothing a user reads points to a
folder beside the checkout, and the papers are cited by name (docs/references.md), not by
the numbers of a private source list ("seed 00x")."""
import argparse
import os
import re
from pathlib import Path

import numpy as np
import pytest

from feedaxis.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")),
         *sorted((ROOT / "fmus").rglob("README.md"))]
LINK = re.compile(r"\]\(([^)\s]+)\)")
OUTSIDE = re.compile(r"\.\./shared|data-format\.md")
SEED_NUMBER = re.compile(r"seeds? 00\d", re.I)
PAGE_NAME = re.compile(r"[\w./-]+\.md\b")


def relative_links(page):
    """The link targets of a Markdown page that are files (not web addresses, not anchors)."""
    targets = [m.group(1) for m in LINK.finditer(page.read_text(encoding="utf-8"))]
    return [t.split("#")[0] for t in targets
            if not re.match(r"[a-z]+:", t) and not t.startswith("#")]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_link_is_a_file_of_the_repository(page):
    for target in relative_links(page):
        resolved = (page.parent / target).resolve()
        assert resolved.is_relative_to(ROOT), f"{target} points outside the repository"
        assert resolved.exists(), f"{target} does not exist"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_page_names_a_source_outside_or_a_seed_number(page):
    text = page.read_text(encoding="utf-8")
    assert not OUTSIDE.findall(text)
    assert not SEED_NUMBER.findall(text)


def test_the_source_names_no_folder_outside_and_no_seed_number():
    files = [*(ROOT / "src" / "feedaxis").rglob("*.py"), *(ROOT / "src" / "feedaxis").rglob("*.toml"),
             *(ROOT / "fmus").rglob("*.py"), *(ROOT / "examples").glob("*.py")]
    found = [f"{path.relative_to(ROOT)}: {match}" for path in files
             for match in OUTSIDE.findall(path.read_text(encoding="utf-8"))
             + SEED_NUMBER.findall(path.read_text(encoding="utf-8"))]
    assert not found


def test_the_tests_name_papers_not_seed_numbers():
    """The tests cite the papers by name too (their folder outside the checkout is CI's
    default for the FMI hosts, conftest.FMI_TOOLS, and may be named)."""
    found = [f"{path.relative_to(ROOT)}: {match}" for path in (ROOT / "tests").rglob("*.py")
             for match in SEED_NUMBER.findall(path.read_text(encoding="utf-8"))]
    assert not found


def help_texts(parser, path=("feedaxis",)):
    """(command path, --help text, not wrapped) of the parser and every subcommand below it."""
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100000"   # argparse wraps at hyphens: keep file names whole
    try:
        found = [(" ".join(path), parser.format_help())]
    finally:
        os.environ.pop("COLUMNS") if previous is None else os.environ.update(COLUMNS=previous)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found += help_texts(sub, (*path, name))
    return found


HELP = help_texts(build_parser())


def test_every_command_has_its_help_checked():
    assert len(HELP) > 20 and any(p == "feedaxis import" for p, _ in HELP)


@pytest.mark.parametrize("command, text", HELP, ids=[p for p, _ in HELP])
def test_help_names_only_pages_of_the_repository(command, text):
    text = " ".join(text.split())
    assert not OUTSIDE.findall(text) and not SEED_NUMBER.findall(text), command
    for name in PAGE_NAME.findall(text):
        assert (ROOT / name).exists() or (ROOT / "docs" / name).exists(), (command, name)


def test_cli_output_cites_papers_by_name(tmp_path, capsys):
    """What the catalog, a demo case and a tracking case without a model print."""
    from feedaxis.examples import write_seed001_case

    case = write_seed001_case(tmp_path / "micro")
    tracking = tmp_path / "tracking"
    tracking.mkdir()
    (tracking / "axis.toml").write_text(
        '[screw]\nlead_mm = 5.0\n[servo]\ncontroller = "pid"\nkp_V_per_mm = 0.8998\n'
        "ki_V_per_mm_s = 0.0006077\nkd_V_s_per_mm = 0.005155\nforce_constant_N_per_V = 100.0\n")
    time_s = np.arange(0.0, 2.0, 1e-3)
    reference_mm = 10.0 * np.sin(2 * np.pi * 0.4 * time_s)
    (tracking / "tracking.csv").write_text("time_s,reference_mm,actual_mm\n" + "".join(
        f"{t!r},{r!r},{r - 0.01!r}\n" for t, r in zip(time_s.tolist(), reference_mm.tolist())))
    printed = []
    for argv in (["effects"], ["compare", str(case)], ["compare", str(tracking)],
                 ["compare", str(tracking), "--json"]):
        assert main(argv) == 0, argv
        printed.append(capsys.readouterr().out)
    assert not SEED_NUMBER.findall("\n".join(printed))
    # the tracking case's empty model is the plant started from the record, not a paper's
    assert "the starting plant" in printed[2]
