"""Build every feedaxis FMU: ``python build_fmu.py [--out DIR]`` (default build/fmus)."""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "src"))

from feedaxis.fmu_build import build_fmus  # noqa: E402

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="build/fmus", help="output folder (default build/fmus)")
    for path in build_fmus(parser.parse_args().out):
        print(path)
