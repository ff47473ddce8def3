"""Every script in examples/ runs as a user would run it and prints what it promises."""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"

# script -> a line of its output (regular expression) that shows it did its job
PROMISES = {
    "loop_on_bundled_case.py": r"^4 rounds, verdict adequate, RMS 0\.05\d+ µm$",
    "own_effect.py": r"^with coupling_ripple: RMS 0\.05\d+ µm .*verdict adequate$",
    "thermal_identification.py": r"^9000 mm/min: thermal error max 60\.\d µm -> [3-5]\.\d µm",
    "cosimulation.py": r"^-?\d+\.\d{3} µm at -?\d+\.\d{4} mm$",
    "ssp_in_libcosim.py": r"^\[\d+\.\d+, -?\d+\.\d+(e-\d+)?\]$",
    "two_axis_circle.py": r"^7540 steps on the measured turn; radial deviation -\d\.\d{3} to \d\.\d{3} µm$",
}


# effect files loaded with --effects (own_effect.py runs coupling_ripple.py)
EFFECT_FILES = {"coupling_ripple.py"}


def test_every_example_is_run_here():
    assert {path.name for path in EXAMPLES.glob("*.py")} == set(PROMISES) | EFFECT_FILES


@pytest.mark.parametrize("script", sorted(PROMISES))
def test_example_runs(script, user_fmu_cache, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    here = tmp_path / "run"   # where the user runs it (tmp_path holds the user cache)
    here.mkdir()
    done = subprocess.run([sys.executable, str(EXAMPLES / script)], cwd=here, env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert re.search(PROMISES[script], done.stdout, re.M), done.stdout
    assert not list(here.iterdir()), "an example leaves files where it is run"
