"""Command line: ``feedaxis <command>``; each command parses, calls the library, prints.

Exit codes: 0 success, 2 bad input (one message on stderr, nothing written), 130 Ctrl-C.
The numerical modules (scipy, matplotlib, pythonfmu: seconds to import) are imported by the
commands that use them, so ``--help`` and ``effects`` answer at once.
"""
from __future__ import annotations

import argparse
import json
import sys
from contextlib import contextmanager
from pathlib import Path

from . import __version__, text
from .case import read_case
from .effects import Model, available_effects, load_model
from .output import write_atomically

CASE_HELP = "case folder: axis.toml + positioning.csv (+ duty.csv), see data-format.md"


@contextmanager
def _progress(label, unit):
    """A tqdm counter on stderr that shows itself only when the work takes over a second."""
    from tqdm import tqdm

    with tqdm(desc=label, unit=unit, delay=1.0, leave=False, file=sys.stderr) as bar:
        yield lambda *_: bar.update()


def _effects(args):
    return available_effects(args.effects or ())


def _starting_model(args, effects):
    return load_model(args.model, effects) if args.model else Model()


def _with_added(model, names, effects):
    """``model`` plus the effects named by ``--add``, in order."""
    for name in names or ():
        if name not in effects:
            raise ValueError(f"--add {name}: unknown effect; known: {', '.join(effects)}")
        if name in model:
            raise ValueError(f"--add {name}: already in the model")
        model = model + effects[name]
    return model


def _emit(args, payload, lines):
    print(json.dumps(payload, indent=2) if args.json else lines)


def _cmd_fit(args):
    from .fit import evaluate, fit

    effects = _effects(args)
    cases = [read_case(folder) for folder in args.cases]
    starting = _starting_model(args, effects)
    model = _with_added(starting, args.add, effects)
    before = evaluate(starting, cases)
    with _progress("fitting", "model evaluations") as tick:
        result = fit(model, cases, progress=tick)
    if args.out:
        write_atomically(args.out, result.model.to_toml())
    payload = {"rms_before_um": before.rms_um, "rms_after_um": result.rms_um,
               "effects": list(result.model.names), "params": result.params(),
               "uncertainties": result.uncertainties, "undetermined": result.undetermined,
               "statistics": vars(result.statistics)}
    _emit(args, payload, text.fit_lines(result, before.rms_um, args.out))


def _cmd_diagnose(args):
    from .diagnose import diagnose

    effects = _effects(args)
    case = read_case(args.case)
    model = _starting_model(args, effects)
    with _progress("diagnosing", "fits") as tick:
        diagnosis = diagnose(case, model, effects, progress=tick)
    _emit(args, diagnosis.to_json(), text.diagnosis_lines(diagnosis))


def _cmd_compare(args):
    from .iso230 import compare

    effects = _effects(args)
    case = read_case(args.case)
    comparison = compare(case, _starting_model(args, effects))
    _emit(args, comparison, text.comparison_lines(comparison))


def _cmd_report(args):
    from .report import write_report

    effects = _effects(args)
    case = read_case(args.case)
    model = _starting_model(args, effects)
    out = Path(args.out or f"{Path(args.case).resolve().name}-report.html")
    write_report(case, model, effects, out)
    _emit(args, {"report": str(out)}, f"report: {out}")


def _cmd_compensate(args):
    from .case import csv_text
    from .compensate import compensate

    case = read_case(args.case)
    result = compensate(case, load_model(args.model, _effects(args)))
    if args.out:
        write_atomically(args.out, csv_text(result.columns()))
    _emit(args, result.to_json(), text.compensation_lines(result, args.out))


def _cmd_effects(args):
    effects = _effects(args)
    payload = {name: {"meaning": e.meaning, "fmu": e.fmu,
                      "parameters": {p.name: {"unit": p.unit, "lower": p.lower, "upper": p.upper,
                                              "meaning": p.meaning} for p in e.parameters}}
               for name, e in effects.items()}
    _emit(args, payload, text.effect_lines(effects))


def _cmd_demo(args):
    from . import demo

    summary = demo.run_demo(args.out, echo=(lambda line: None) if args.json else print)
    if args.json:
        print(json.dumps(summary, indent=2))


def _cmd_build_fmus(args):
    from . import fmu_build

    paths = fmu_build.build_fmus(args.out)
    _emit(args, [str(p) for p in paths], "\n".join(str(p) for p in paths))


def _add_model_options(sub, model_help="starting model (TOML); without it the model is empty",
                       required=False):
    sub.add_argument("--model", metavar="M.toml", help=model_help, required=required)
    sub.add_argument("--effects", metavar="F.py", action="append",
                     help="Python file with your own effects (repeatable); see the README")


def build_parser():
    """The argparse parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="feedaxis",
        description="Digital twin of a ball-screw feed axis. Compare a model with "
                    "laser-interferometer and thermal-test data, see where it fails, learn "
                    "which physical effect is missing, add it, watch the error fall. The "
                    "model runs as FMI 2.0 FMUs (NpidServo, StepperError, GeometricError, "
                    "ThermalScrew).",
        epilog="Start with `feedaxis demo`. Exit codes: 0 ok, 2 bad input, 130 interrupted.")
    parser.add_argument("--version", action="version", version=f"feedaxis {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    sub = commands.add_parser(
        "demo", help="the whole loop on the bundled seed 001 case, then the FMUs",
        description="Diagnose, add the missing effect, refit, until the verdict is adequate, "
                    "on the bundled seed 001 micro ball screw; write the model, the report "
                    "and the FMUs into --out and check the FMUs reproduce the fitted model.")
    sub.add_argument("--out", default="feedaxis-demo", help="output folder (default: feedaxis-demo)")
    sub.set_defaults(handler=_cmd_demo)

    sub = commands.add_parser(
        "fit", help="fit a model's effects to one or several cases",
        description="Bounded least squares over every parameter of the model's effects "
                    "(and of --add EFFECT), jointly over all CASE folders.")
    sub.add_argument("cases", nargs="+", metavar="CASE", help=CASE_HELP)
    _add_model_options(sub)
    sub.add_argument("--add", metavar="EFFECT", action="append",
                     help="add an effect by name (repeatable); see `feedaxis effects`")
    sub.add_argument("--out", metavar="M2.toml", help="write the fitted model here")
    sub.set_defaults(handler=_cmd_fit)

    sub = commands.add_parser(
        "diagnose", help="where the model fails and which effect is missing",
        description="Refit the model, fit each missing effect on top and rank them by BIC, "
                    "describe structure no effect explains, and give a verdict: adequate, "
                    "missing_effect or unexplained.")
    sub.add_argument("case", metavar="CASE", help=CASE_HELP)
    _add_model_options(sub)
    sub.set_defaults(handler=_cmd_diagnose)

    sub = commands.add_parser(
        "compare", help="ISO 230-2 figures of the measurement and of the residual",
        description="ISO 230-2 accuracy, repeatability, reversal and systematic deviation of "
                    "the measured runs and of what is left after the model, side by side.")
    sub.add_argument("case", metavar="CASE", help=CASE_HELP)
    _add_model_options(sub, "model (TOML) as fitted; without it the model is empty")
    sub.set_defaults(handler=_cmd_compare)

    sub = commands.add_parser(
        "report", help="self-contained HTML page with the plots",
        description="Measurement against model, residual with the marked wavelengths, "
                    "spectrum, each effect's contribution, the error ladder, the diagnosis.")
    sub.add_argument("case", metavar="CASE", help=CASE_HELP)
    _add_model_options(sub, "fitted model (TOML)", required=True)
    sub.add_argument("--out", metavar="REPORT.html", help="default: <case>-report.html")
    sub.set_defaults(handler=_cmd_report)

    sub = commands.add_parser(
        "compensate", help="thermal correction at each sample and the error it leaves",
        description="Apply the model's thermal effects (thermal_screw, ambient_expansion) as "
                    "a compensation to a thermal case, as seed 003 §5.2: the thermal error is "
                    "each target's drift from its first visit; print its max and RMS before "
                    "and after, per target and over time.")
    sub.add_argument("case", metavar="CASE", help=CASE_HELP)
    _add_model_options(sub, "fitted model with thermal_screw (TOML)", required=True)
    sub.add_argument("--out", metavar="COMPENSATION.csv",
                     help="write per sample: time_s, target_mm, direction, measured_um, "
                          "thermal_error_um, correction_um, left_um")
    sub.set_defaults(handler=_cmd_compensate)

    sub = commands.add_parser("effects", help="list the effect catalog (and your own)",
                              description="Each effect's meaning, parameters and FMU.")
    sub.add_argument("--effects", metavar="F.py", action="append", help="your own effects file")
    sub.set_defaults(handler=_cmd_effects)

    sub = commands.add_parser(
        "build-fmus", help="build the four FMUs",
        description="Build NpidServo, StepperError, GeometricError and ThermalScrew into --out.")
    sub.add_argument("--out", default="build/fmus", help="FMU folder (default: build/fmus)")
    sub.set_defaults(handler=_cmd_build_fmus)

    for sub in commands.choices.values():
        sub.add_argument("--json", action="store_true", help="print machine-readable JSON")
    return parser


def main(argv=None):
    """Entry point of the ``feedaxis`` console script; returns the exit code."""
    from threadpoolctl import threadpool_limits

    args = build_parser().parse_args(argv)
    try:
        with threadpool_limits(limits=1, user_api="blas"):  # small matrices: threads only cost
            args.handler(args)
    except KeyboardInterrupt:
        print("feedaxis: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        sys.stderr.close()
        return 0
    except ValueError as error:
        print(f"feedaxis: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
