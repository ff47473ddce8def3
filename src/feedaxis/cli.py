"""Command line: ``feedaxis <command>``; each command parses, calls the library, prints."""
from __future__ import annotations

import argparse
import json
import sys

from . import demo, fmu_build


def _cmd_demo(args):
    summaries = demo.run_demo(args.out, echo=(lambda line: None) if args.json else print)
    if args.json:
        print(json.dumps(summaries, indent=2))


def _cmd_build_fmus(args):
    paths = fmu_build.build_fmus(args.out)
    if args.json:
        print(json.dumps([str(p) for p in paths]))
    else:
        print("\n".join(str(p) for p in paths))


def build_parser():
    """The argparse parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="feedaxis",
        description="Digital twin of a ball-screw feed axis: FMI 2.0 co-simulation FMUs "
                    "(NpidServo, StepperError, GeometricError, ThermalScrew) over one physics core.")
    commands = parser.add_subparsers(dest="command", required=True)
    demo_parser = commands.add_parser(
        "demo", help="build the four FMUs and run each through fmpy, with a short summary",
        description="Build the four FMUs into --out and run each through fmpy on a scripted "
                    "input, printing one line per FMU next to the paper's figure.")
    build_parser_ = commands.add_parser(
        "build-fmus", help="build the four FMUs",
        description="Build NpidServo, StepperError, GeometricError and ThermalScrew into --out.")
    for sub, handler in ((demo_parser, _cmd_demo), (build_parser_, _cmd_build_fmus)):
        sub.add_argument("--out", default="build/fmus", help="FMU folder (default: build/fmus)")
        sub.add_argument("--json", action="store_true", help="print machine-readable JSON")
        sub.set_defaults(handler=handler)
    return parser


def main(argv=None):
    """Entry point of the ``feedaxis`` console script; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        args.handler(args)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except ValueError as error:
        print(f"feedaxis: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
