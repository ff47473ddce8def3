"""Build every feedaxis FMU: ``python build_fmu.py [--out DIR] [--standalone]`` (default
build/fmus; ``--standalone``: each FMU carries its Python, see docs/fmu-hosts.md)."""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "src"))

from feedaxis.fmu_build import build_fmus  # noqa: E402

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="build/fmus", help="output folder (default build/fmus)")
    parser.add_argument("--standalone", action="store_true",
                        help="each FMU carries the Python its physics needs")
    args = parser.parse_args()
    for path in build_fmus(args.out, standalone=args.standalone):
        print(path)
