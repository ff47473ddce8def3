"""The installed package carries every subpackage of src/ and the FMU sources of fmus/."""
from pathlib import Path

from setuptools import find_packages

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]


def test_pyproject_lists_every_package():
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    data = [f"feedaxis.data.{folder.name}" for folder in (ROOT / "src/feedaxis/data").iterdir()
            if folder.is_dir() and folder.name != "__pycache__"]
    fmus = [f"feedaxis.fmus.{'.'.join(folder.relative_to(ROOT / 'fmus').parts)}"
            for folder in (ROOT / "fmus").rglob("*")
            if folder.is_dir() and "__pycache__" not in folder.parts]
    assert sorted(setuptools["packages"]) == sorted(
        find_packages(ROOT / "src") + ["feedaxis.fmus"] + data + fmus)
    assert setuptools["package-dir"]["feedaxis.fmus"] == "fmus"
