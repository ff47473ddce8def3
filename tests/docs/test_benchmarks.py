"""Every benchmark runs in CI at its smallest size (``--smoke``): it must finish, not meet
a time, so the figures docs/speed.md prints (``benchmarks/speed_page.py``) cannot silently
break. A benchmark whose tables have a shape to keep is checked for it (``OUTPUT_CHECKS``);
one that needs what pip does not install says so (``NEEDS``: skipped off CI, failed on it)."""
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import unavailable
from feedaxis.fmu_build import AXIS_FMU_NAMES
from feedaxis.toolchain import c_compiler

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = sorted(p.name for p in (ROOT / "benchmarks").glob("*.py")
                    if p.name.startswith(("bench_", "stress_")))


def load_benchmark(name):
    sys.path.insert(0, str(ROOT / "benchmarks"))  # the scripts import benchmarks/common.py
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def fmi_floor_prints_every_ratio(out):
    """Per controller mode a row for each FMU and the axis (native, empty and feedaxis cost,
    both ratios with their quartiles), the servo's NPID and friction ratios to PID, and a
    first-start time for each FMU and the servo in NPID."""
    bench = load_benchmark("bench_fmi_floor")
    for mode in bench.MODES:
        table = out.split(f"\n{mode}: ")[1]
        for row in (*AXIS_FMU_NAMES, "full axis"):
            cells = next(line for line in table.splitlines() if row in line).split()
            assert len(cells) >= 8, cells  # native, empty, feedaxis, two ratios and quartiles
    assert "NpidServo NPID / PID: " in out and "NpidServo friction / PID: " in out
    starts = out.split("first instantiate + initialisation")[1].splitlines()
    assert sum(any(label in line for line in starts)
               for label in (*AXIS_FMU_NAMES, "NpidServo NPID")) == len(AXIS_FMU_NAMES) + 1


NEEDS = {"bench_fmi_floor.py": lambda: None if c_compiler() else
         "no C compiler for the native FMUs of the floor (cc or gcc, or set CC)"}
OUTPUT_CHECKS = {"bench_fmi_floor.py": fmi_floor_prints_every_ratio}


@pytest.mark.parametrize("script", BENCHMARKS)
def test_the_benchmark_runs_at_its_smallest_size(script, tmp_path):
    missing = NEEDS[script]() if script in NEEDS else None
    if missing is not None:
        unavailable(missing)
    environment = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), "--smoke"],
                          cwd=tmp_path, env=environment, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip()
    if script in OUTPUT_CHECKS:
        OUTPUT_CHECKS[script](done.stdout)


def test_the_speed_page_collects_every_benchmark():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import speed_page

    assert [p.name for p in speed_page.scripts()] == BENCHMARKS
    title, description = speed_page.described(ROOT / "benchmarks" / "bench_diagnose_scale.py")
    assert title.startswith("Analysis at scale") and "10^6" in description
