"""Writes docs/speed.md from the benchmarks themselves, so its figures cannot go stale.

Runs every ``benchmarks/bench_*.py`` (and ``stress_*.py``) at its default sizes, one after
the other, and writes one section per benchmark: its title and description (the script's
docstring), the command, and what it printed, under the machine and the date of the run.

Run: ``python benchmarks/speed_page.py [--only NAME ...] [--out docs/speed.md]`` (about an
hour on the 2-core machine; ``--only`` reruns some and keeps the other sections).
"""
from __future__ import annotations

import argparse
import ast
import os
import re
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from common import machine  # noqa: E402

HEADER = """# Speed

Every figure on this page is printed by a script in `benchmarks/`, measured side by side in
one run (ratios, medians of interleaved repeats; this machine is shared, so spreads are
given), under the machine and the date it ran on. The page is written by
`python benchmarks/speed_page.py`: rerun it to refresh (`--only NAME` for one script).
"""


def scripts():
    """The benchmark scripts, in name order."""
    return sorted(p for p in HERE.glob("*.py") if p.name.startswith(("bench_", "stress_")))


def described(path):
    """(title, description) from the script's docstring: its first paragraph, the rest."""
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or path.stem
    title, _, rest = doc.partition("\n\n")
    return " ".join(title.split()).rstrip("."), rest.strip()


def section(path, measured):
    """The page's section of ``path``: its title and description from the script as it is
    now, then ``measured`` (the command, the machine and what it printed)."""
    title, description = described(path)
    return f"## {title}\n\n{description}\n\n{measured}"


def measured_now(path, output):
    return (f"`python benchmarks/{path.name}` on {machine()}:\n\n```text\n{output.rstrip()}\n"
            "```\n")


def run(path):
    """The benchmark's standard output (its failure said on the page, not hidden)."""
    environment = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    done = subprocess.run([sys.executable, str(path)], cwd=ROOT, capture_output=True,
                          text=True, env=environment)
    if done.returncode:
        last = (done.stderr.strip().splitlines() or [""])[-1]
        return f"{done.stdout}\n(exit {done.returncode}: {last})"
    return done.stdout


def existing_measurements(page):
    """{script name: what it measured} (the command line with the machine, and the output)
    of a page this script wrote before."""
    if not page.exists():
        return {}
    found = {}
    for block in re.split(r"\n(?=## )", page.read_text(encoding="utf-8")):
        match = re.search(r"^`python benchmarks/(\S+\.py)` on .*", block, flags=re.M | re.S)
        if match and block.startswith("## "):
            found[match.group(1)] = match.group(0).rstrip() + "\n"
    return found


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="*", default=None, metavar="NAME",
                        help="run only these scripts (e.g. bench_fmi_floor); keep the rest")
    parser.add_argument("--out", default=str(ROOT / "docs" / "speed.md"))
    args = parser.parse_args(argv)
    page = Path(args.out)
    measured = existing_measurements(page)
    for path in scripts():
        if args.only is None or path.stem in args.only:
            print(f"running {path.name} ...", file=sys.stderr, flush=True)
            measured[path.name] = measured_now(path, run(path))
    body = "\n".join(section(path, measured[path.name]) for path in scripts()
                     if path.name in measured)
    page.write_text(f"{HEADER}\n{body}", encoding="utf-8")
    print(f"written: {page}")


if __name__ == "__main__":
    main()
