"""docs/cosim.md and docs/fmus.md: the system table is current and every FMU snippet runs."""
import re
import shutil
from pathlib import Path

import pytest

from feedaxis.cli import main
from feedaxis.cosim.system import default_axis, markdown_tables

DOCS = Path(__file__).resolve().parent.parent / "docs"
COSIM = (DOCS / "cosim.md").read_text(encoding="utf-8")
SNIPPETS = dict(re.findall(r"<!-- snippet: ([\w-]+) -->\n```python\n(.*?)```",
                           COSIM + (DOCS / "fmus.md").read_text(encoding="utf-8"), re.S))


def test_docs_system_table_is_generated_from_the_system_description():
    table = re.search(r"<!-- system table:[^\n]*-->\n(.*?)\n<!-- end of system table -->",
                      COSIM, re.S).group(1)
    assert table == markdown_tables(default_axis()), \
        "regenerate it with: python -m feedaxis.cosim.system"


@pytest.fixture
def user_folder(user_fmu_cache, tmp_path, monkeypatch):
    """A working folder with axis.ssp, axis.fmu and build/fmus/, and a user cache holding
    the FMUs."""
    monkeypatch.chdir(tmp_path)
    assert main(["export-ssp", "axis.ssp"]) == 0
    assert main(["export-fmu", "axis.fmu"]) == 0
    shutil.copytree(user_fmu_cache, tmp_path / "build" / "fmus")   # docs/fmus.md: build/fmus/<Name>.fmu
    return tmp_path


@pytest.mark.parametrize("name", ["fmpy-ssp", "container", "fmpy-servo"])
def test_docs_snippet_runs(user_folder, capsys, name):
    capsys.readouterr()
    exec(compile(SNIPPETS[name], f"docs snippet {name}", "exec"), {})
    printed = capsys.readouterr().out
    assert re.search(r"\d", printed), printed
