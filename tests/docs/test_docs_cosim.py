"""docs/cosim.md and docs/fmus.md: the system table is current and every FMU snippet runs."""
import json
import re
import shutil
from pathlib import Path

import pytest

from feedaxis.cli import main
from feedaxis.cosim.system import default_axis, markdown_tables

DOCS = Path(__file__).resolve().parents[2] / "docs"
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


def test_export_ssp_states_its_open_inputs_and_the_docs_say_so(fmu_paths, tmp_path, capsys):
    """OMSimulator runs an SSP whose position_ref_mm nobody drives as a standing axis, without
    a word: the export names every open input with its start value, and so do the docs."""
    folder = fmu_paths["NpidServo"].parent
    assert main(["export-ssp", str(tmp_path / "axis.ssp"), "--fmus", str(folder), "--json"]) == 0
    opened = json.loads(capsys.readouterr().out)["open_inputs"]
    assert [(i["input"], i["start"], i["unit"]) for i in opened] == [
        ("NpidServo.position_ref_mm", 0.0, "mm"), ("NpidServo.disturbance_N", 0.0, "N"),
        ("ThermalScrew.ambient_C", 20.0, "degC")]
    assert main(["export-ssp", str(tmp_path / "axis.ssp"), "--fmus", str(folder)]) == 0
    printed = capsys.readouterr().out
    assert "NpidServo.position_ref_mm = 0 mm" in printed and "standing axis" in printed
    hosts = (DOCS / "fmu-hosts.md").read_text(encoding="utf-8")
    for connector, start, unit in [(i["input"], i["start"], i["unit"]) for i in opened]:
        assert f"| `{connector}` |" in hosts
    assert "open_inputs" in COSIM and "standing axis" in COSIM


def test_the_host_requirements_are_a_page_of_the_docs_site():
    """docs/fmus.md named fmus/README.md as text only: the requirements (the exact
    interpreter, the variables, the standalone build) are a page in the site's navigation."""
    navigation = (DOCS.parent / "mkdocs.yml").read_text(encoding="utf-8")
    assert re.search(r"^\s+- [^:]+: fmu-hosts\.md$", navigation, re.M)
    assert "](fmu-hosts.md)" in (DOCS / "fmus.md").read_text(encoding="utf-8")
    hosts = (DOCS / "fmu-hosts.md").read_text(encoding="utf-8")
    for needed in ("minor version must match", "FEEDAXIS_PYTHON", "FEEDAXIS_LIBPYTHON",
                   "--standalone", "Windows"):
        assert needed in hosts, needed
