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
from .errors import InputError
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


def _parameter_value(text):
    """``--set`` value: true/false, an integer, a number, else the text."""
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    for convert in (int, float):
        try:
            return convert(text)
        except ValueError:
            pass
    return text


def _axis_overrides(args):
    """{component: {parameter: value}} from --model/--axis and --set, --set last."""
    overrides = {}
    if args.model:
        if not args.axis:
            raise ValueError("--model needs --axis (the axis.toml or case folder it was "
                             "fitted on): the FMU parameters depend on the axis")
        from .case import read_axis

        axis_path = Path(args.axis)
        axis = read_axis(axis_path / "axis.toml" if axis_path.is_dir() else axis_path)
        overrides = load_model(args.model, _effects(args)).fmu_parameters(axis)
    for item in args.set or ():
        name, _, value = item.partition("=")
        component, _, parameter = name.partition(".")
        if not (component and parameter and value):
            raise ValueError(f"--set {item}: expected COMPONENT.PARAMETER=VALUE, e.g. "
                             "NpidServo.nonlinear=true")
        overrides.setdefault(component, {})[parameter] = _parameter_value(value)
    return overrides


def _axis_system(args):
    from .cosim.system import default_axis

    for option, value in (("--step-ms", args.step_ms), ("--thermal-step-s", args.thermal_step_s)):
        if not value > 0:
            raise ValueError(f"{option} must be > 0, got {value:g}")
    step_s = args.step_ms * 1e-3
    return default_axis(step_s, step_s, args.thermal_step_s).with_parameters(
        _axis_overrides(args))


def _fmu_paths(args):
    if args.fmus:
        from .fmu_build import FMU_NAMES

        paths = {name: Path(args.fmus) / f"{name}.fmu" for name in FMU_NAMES}
        missing = [str(p) for p in paths.values() if not p.exists()]
        if missing:
            raise ValueError(f"--fmus {args.fmus}: missing {', '.join(missing)}")
        return paths
    from .cosim.fmu_cache import cached_fmus

    return cached_fmus()


@contextmanager
def _step_progress():
    """A tqdm bar over macro steps on stderr, shown when the run takes over a second."""
    from tqdm import tqdm

    with tqdm(desc="simulating", unit="step", unit_scale=True, delay=1.0, leave=False,
              file=sys.stderr) as bar:
        def update(done_steps, total_steps):
            bar.total = total_steps
            bar.update(done_steps - bar.n)

        yield update


def _simulate(args, scenario):
    """Run one scenario into a new case folder; Ctrl-C keeps what was computed."""
    from .cosim.master import Master
    from .cosim.scenarios import ScenarioInterrupted

    if Path(args.out).exists():
        raise ValueError(f"{args.out}: already exists; choose a new case folder")
    system = _axis_system(args)
    with Master(system, _fmu_paths(args)) as master:
        try:
            with _step_progress() as progress:
                return scenario(master, progress)
        except ScenarioInterrupted as stopped:
            print(f"feedaxis: {stopped.message}", file=sys.stderr)
            raise


def _cmd_simulate_iso230(args):
    from .cosim.scenarios import iso230_targets, simulate_iso230

    targets = iso230_targets(args.targets, args.spacing_mm, args.first_mm)
    summary = _simulate(args, lambda master, progress: simulate_iso230(
        args.out, master, targets, args.runs, args.feed_mm_min, args.dwell_s, args.overrun_mm,
        progress=progress))
    _emit(args, summary, f"{args.out}: {summary['samples']} samples, {args.targets} targets x "
                         f"{args.runs} runs each direction; deviation "
                         f"{summary['error_min_um']:.3f} to {summary['error_max_um']:.3f} um")


def _cmd_simulate_thermal(args):
    from .case import read_duty
    from .cosim.scenarios import simulate_thermal

    if not Path(args.duty).is_file():
        raise ValueError(f"--duty {args.duty}: file not found")
    duty = read_duty(args.duty)
    targets = _numbers(args.targets, "--targets")
    summary = _simulate(args, lambda master, progress: simulate_thermal(
        args.out, master, duty, targets, args.every_s, args.feed_mm_min, args.dwell_s,
        progress=progress))
    _emit(args, summary, f"{args.out}: {summary['samples']} samples (duty.csv + "
                         f"positioning.csv); deviation {summary['error_min_um']:.3f} to "
                         f"{summary['error_max_um']:.3f} um")


def _cmd_simulate_tracking(args):
    from .cosim.scenarios import simulate_tracking

    force = {} if args.force_N is None else {"force_N": args.force_N}
    summary = _simulate(args, lambda master, progress: simulate_tracking(
        args.out, master, args.frequency_hz, args.amplitude_mm, args.duration_s,
        args.controller, args.spindle_rpm, progress=progress, **force))
    _emit(args, summary, f"{args.out}/tracking.csv: {args.controller.upper()}, "
                         f"{args.frequency_hz:g} Hz, {args.amplitude_mm:g} mm"
                         + (f", cutting force at {args.spindle_rpm:g} rpm"
                            if args.spindle_rpm else "")
                         + f"; after the first second: max tracking error "
                           f"{summary['max_tracking_error_mm']:.4f} mm, RMS "
                           f"{summary['rms_tracking_error_mm']:.4f} mm")


def _numbers(text, option):
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(f"{option} {text}: expected comma-separated numbers, e.g. 10,100,190") \
            from None
    return values


def _cmd_export_ssp(args):
    from .cosim.ssp import export_ssp

    system = _axis_system(args)
    path = export_ssp(args.out, system, _fmu_paths(args), args.stop_time,
                      args.osp_step_hints)
    _emit(args, {"ssp": str(path)}, f"{path}: SystemStructure.ssd, a parameter-values file "
                                    "(.ssv) per component and the four FMUs")



def _cmd_export_fmu(args):
    from .cosim.container import export_container_fmu

    system = _axis_system(args)
    path = export_container_fmu(args.out, system, _fmu_paths(args))
    _emit(args, {"fmu": str(path)}, f"{path}: the axis as one FMU (fmpy container of the four "
                                    f"FMUs, one {args.step_ms:g} ms step for all)")


def _add_model_options(sub, model_help="starting model (TOML); without it the model is empty",
                       required=False):
    sub.add_argument("--model", metavar="M.toml", help=model_help, required=required)
    sub.add_argument("--effects", metavar="F.py", action="append",
                     help="Python file with your own effects (repeatable); see the README")


def _add_motion_options(sub):
    sub.add_argument("--feed-mm-min", type=float, default=3000.0,
                     help="feed of the moves between targets (default 3000 mm/min)")
    sub.add_argument("--dwell-s", type=float, default=0.5,
                     help="dwell at each target before the sample (default 0.5 s)")


def _add_axis_options(sub):
    sub.add_argument("--step-ms", type=float, default=1.0,
                     help="macro step = servo, motor and geometry step (default 1 ms)")
    sub.add_argument("--thermal-step-s", type=float, default=0.1,
                     help="ThermalScrew step, a multiple of the macro step (default 0.1 s)")
    sub.add_argument("--set", metavar="COMPONENT.PARAMETER=VALUE", action="append",
                     help="parameter value (repeatable), e.g. NpidServo.nonlinear=true")
    _add_model_options(sub, "fitted model (TOML): its FMU parameter values (needs --axis)")
    sub.add_argument("--axis", metavar="AXIS", help="axis.toml or case folder the model was "
                                                    "fitted on")
    sub.add_argument("--fmus", metavar="DIR", help="use the FMUs in DIR (default: built once "
                                                   "into the user cache)")


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

    sub = commands.add_parser(
        "simulate", help="run a scenario on the co-simulated axis, write a case folder",
        description="Co-simulate the four FMUs as one axis (the fmpy master) through a "
                    "scenario and write the result as a measurement case (data-format.md), "
                    "ready for fit, diagnose and compare. iso230 and thermal run the servo "
                    "with a type-1 plant (NpidServo.plant_stiffness_per_s2 = 0: seed 002's "
                    "193.3 leaves a static error of target/364); --set overrides it. Ctrl-C "
                    "stops and keeps what was computed.")
    scenarios = sub.add_subparsers(dest="scenario", required=True, metavar="SCENARIO")
    scenario = scenarios.add_parser(
        "iso230", help="ISO 230-2 positioning test -> axis.toml + positioning.csv",
        description="Targets P_i = (i-1) p + r_i (r_i a different small offset at each), "
                    "RUNS runs approaching every target in + and in -, overrun beyond the "
                    "end targets, dwell, then the deviation table position - target.")
    scenario.add_argument("--targets", type=int, default=11, help="number of targets (default 11)")
    scenario.add_argument("--spacing-mm", type=float, default=50.0,
                          help="target spacing p (default 50)")
    scenario.add_argument("--first-mm", type=float, default=0.0, help="P_1 before offset (default 0)")
    scenario.add_argument("--runs", type=int, default=5, help="runs each direction (default 5)")
    scenario.add_argument("--overrun-mm", type=float, default=2.0, help="default 2")
    _add_motion_options(scenario)
    scenario.set_defaults(handler=_cmd_simulate_iso230)

    scenario = scenarios.add_parser(
        "thermal", help="duty cycle with measurement passes -> + duty.csv",
        description="Drive the axis through DUTY (duty.csv format) with a measurement pass "
                    "over --targets at t = 0, every --every-s of duty time and at the end; "
                    "write the motion as duty.csv and the samples (with time_s) as "
                    "positioning.csv.")
    scenario.add_argument("--duty", required=True, metavar="duty.csv", help="the heating duty")
    scenario.add_argument("--targets", required=True, metavar="X1,X2,...",
                          help="targets of each measurement pass (mm), visited in this order")
    scenario.add_argument("--every-s", type=float, default=600.0,
                          help="duty time between measurement passes (default 600 s)")
    _add_motion_options(scenario)
    scenario.set_defaults(handler=_cmd_simulate_thermal)

    scenario = scenarios.add_parser(
        "tracking", help="sinusoidal tracking, PID or NPID (seed 002) -> tracking.csv",
        description="Reference A sin(2 pi f t); prints the maximum and RMS tracking error "
                    "after the first second. --spindle-rpm adds a milling force at the "
                    "tooth-passing frequency (mean force ~ 1500/rpm; an assumption, seed 002 "
                    "publishes none).")
    scenario.add_argument("--frequency-hz", type=float, default=0.4, help="default 0.4")
    scenario.add_argument("--amplitude-mm", type=float, default=10.0, help="default 10")
    scenario.add_argument("--duration-s", type=float, default=10.0, help="default 10")
    scenario.add_argument("--controller", choices=("pid", "npid"), default="pid")
    scenario.add_argument("--spindle-rpm", type=float, help="e.g. 1500, 2500, 3500")
    scenario.add_argument("--force-N", type=float,
                          help="cutting force F0 at 1500 rpm (default 1.4 N: fitted to one "
                               "row of seed 002 Table 2)")
    scenario.set_defaults(handler=_cmd_simulate_tracking)
    for scenario in scenarios.choices.values():
        scenario.add_argument("out", metavar="OUT", help="case folder to create (must not exist)")
        _add_axis_options(scenario)
        scenario.add_argument("--json", action="store_true", help="print machine-readable JSON")

    sub = commands.add_parser(
        "export-ssp", help="the axis as an SSP file for other FMI system simulators",
        description="Write OUT.ssp: SystemStructure.ssd (components, connections, step "
                    "sizes), resources/<Component>.ssv (parameter values) and the four FMUs. "
                    "Runs in fmpy.ssp.simulate_ssp, OSP libcosim (libcosimpy), OMSimulator and "
                    "ecos; see README.")
    sub.add_argument("out", metavar="OUT.ssp", help="SSP file to write")
    sub.add_argument("--stop-time", type=float, default=1.0, metavar="S",
                     help="DefaultExperiment stopTime in s (default 1)")
    sub.add_argument("--osp-step-hints", action="store_true",
                     help="add OSP's per-component step sizes (libcosim runs the thermal screw "
                          "at its own step); OMSimulator 3.0 refuses such a file")
    _add_axis_options(sub)
    sub.set_defaults(handler=_cmd_export_ssp)

    sub = commands.add_parser(
        "export-fmu", help="the axis as one FMU (fmpy container FMU)",
        description="Wrap the four FMUs in one FMI 2.0 co-simulation FMU with fmpy's container "
                    "FMU: inputs position_ref_mm, disturbance_N, ambient_C; every component "
                    "output; the parameter values as fixed parameters. All four FMUs step at "
                    "the container's one step (--step-ms; --thermal-step-s does not apply), "
                    "Jacobi: the error FMUs see the servo one step late.")
    sub.add_argument("out", metavar="OUT.fmu", help="FMU file to write")
    _add_axis_options(sub)
    sub.set_defaults(handler=_cmd_export_fmu)

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
    except (InputError, ValueError) as error:
        print(f"feedaxis: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
