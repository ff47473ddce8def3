"""Benchmarks run at a tiny size (a smoke run: they must finish and print, not meet a time)."""
import importlib.util
import os
import shutil
from pathlib import Path

import pytest

from feedaxis.fmu_build import FMU_NAMES

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def load_benchmark(name):
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_fmi_floor_benchmark_prints_every_ratio(fmu_paths, capsys):
    if not (shutil.which("cc") or shutil.which("gcc")):
        if os.environ.get("CI") == "true":
            pytest.fail("CI requires a C compiler for the native floor")
        pytest.skip("no C compiler for the native FMUs of the floor")
    bench = load_benchmark("bench_fmi_floor")
    folder = next(iter(fmu_paths.values())).parent
    bench.main(["--repeats", "2", "--steps", "3", "--starts", "1", "--fmus", str(folder)])
    out = capsys.readouterr().out
    for mode in bench.MODES:
        table = out.split(f"\n{mode}: ")[1]
        for row in (*FMU_NAMES, "full axis"):
            cells = next(line for line in table.splitlines() if row in line).split()
            assert len(cells) >= 8, cells  # native, empty, feedaxis, two ratios and quartiles
    assert "NpidServo NPID / PID: " in out and "NpidServo friction / PID: " in out
    starts = out.split("first instantiate + initialisation")[1].splitlines()
    assert sum(any(label in line for line in starts)
               for label in (*FMU_NAMES, "NpidServo NPID")) == len(FMU_NAMES) + 1
