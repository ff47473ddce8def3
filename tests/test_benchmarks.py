"""Every benchmark runs in CI at its smallest size (``--smoke``): it must finish, not meet
a time, so the figures docs/speed.md prints (``benchmarks/speed_page.py``) cannot silently
break."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = sorted(p.name for p in (ROOT / "benchmarks").glob("*.py")
                    if p.name.startswith(("bench_", "stress_")))


@pytest.mark.parametrize("script", BENCHMARKS)
def test_the_benchmark_runs_at_its_smallest_size(script, tmp_path):
    environment = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), "--smoke"],
                          cwd=tmp_path, env=environment, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip()


def test_the_speed_page_collects_every_benchmark():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import speed_page

    assert [p.name for p in speed_page.scripts()] == BENCHMARKS
    title, description = speed_page.described(ROOT / "benchmarks" / "bench_diagnose_scale.py")
    assert title.startswith("Analysis at scale") and "10^6" in description
