"""Command line: ``feedaxis <command>``; each command parses, calls the library, prints.

Exit codes: 0 success, 2 bad input (an :class:`~feedaxis.errors.InputError`: one message on
stderr naming the file, row and column or the option, nothing written), 1 a bug (one line;
``--debug`` shows the traceback), 130 Ctrl-C (143 SIGTERM, 129 SIGHUP). With ``--json`` every
result and every error is strict JSON on stdout (no NaN or Infinity: a value that is not finite is ``null``).
The numerical modules (scipy, matplotlib, pythonfmu: seconds to import) are imported by the
commands that use them, so ``--help`` and ``effects`` answer at once.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from contextlib import contextmanager
from pathlib import Path

from . import __version__, text
from . import stop
from .case import FOLLOW_LINKS, read_case
from .comptable import CONTROLLERS
from .console import fail
from .errors import DISK_STATE_ERRORS, InputError, check_writable_target, json_safe, write_error
from .effects import Model, available_effects, load_model
from .output import refuse_overwriting_inputs, write_atomically
from .comptable.table import TABLE_TOLERANCE_UM
from .importers.wide_csv import column_map
from .uncertainty.correction import OPTION as CORRECTION_OPTION, OPTION_HELP as CORRECTION_HELP
from .uncertainty.correction import MATERIAL, corrected_case, temperature_option

CASE_HELP = ("case folder: axis.toml + positioning.csv (+ duty.csv), or axis.toml with [servo] "
             "+ tracking.csv; see docs/case-format.md")

# Each command is registered beside its handler: @command(NAME, add_parser arguments,
# options=FUNCTION adding its arguments); build_parser adds them in this file's order.
COMMANDS = []


def command(name, options=None, **parser_kwargs):
    """Register the decorated handler as ``feedaxis NAME``."""
    def register(handler):
        COMMANDS.append((name, parser_kwargs, options, handler))
        return handler
    return register


def command_group(name, options, **parser_kwargs):
    """Register ``feedaxis NAME`` whose subcommands (added by ``options``) carry the
    handlers, as ``simulate`` and the scenarios of the kinds of measurement."""
    COMMANDS.append((name, parser_kwargs, options, None))


@contextmanager
def _progress(label, unit):
    """A tqdm counter on stderr that shows itself only when the work takes over a second
    and then redraws every second (a long step shows its elapsed time, not a frozen line);
    the callback takes an optional label of the step under way, or ``total=N``: N more
    steps at most (the bar's total grows by N, nothing is counted)."""
    import threading

    from tqdm import tqdm

    with tqdm(desc=label, unit=unit, delay=1.0, leave=False, file=sys.stderr,
              disable=None) as bar:  # None: off when stderr is no terminal (a log file)
        def tick(step=None, total=None):
            if total is not None:
                bar.total = (bar.total or 0) + total
                return
            if step:
                bar.set_postfix_str(str(step), refresh=False)
            bar.update()

        done = threading.Event()

        def redraw():
            while not done.wait(1.0):
                bar.refresh()

        redrawing = threading.Thread(target=redraw, daemon=True)
        if not bar.disable:
            redrawing.start()
        try:
            yield tick
        finally:
            done.set()
            if redrawing.is_alive():
                redrawing.join()


def _effects(args, cases=()):
    """The effects by name: the catalog, the user's (--effects) and those a case's kind
    makes for it (a circular test: each axis's and the machine's, ``backlash@X``), without
    those acting on kinds the case does not hold."""
    effects = available_effects(args.effects or ())
    for case in cases:
        own = _kind_part(case, "case_effects")
        if own is not None:
            held = set(case.samples)
            effects = {**{name: e for name, e in effects.items()
                          if e.measurement is None or e.measurement in held},
                       **own(case)}
    return effects


def _starting_model(args, effects):
    return load_model(args.model, effects) if args.model else Model()


def _with_added(model, names, effects):
    """``model`` plus the effects named by ``--add``, in order."""
    for name in names or ():
        if name not in effects:
            raise InputError(f"unknown effect; known: {', '.join(effects)}",
                             parameter=f"--add {name}")
        if name in model:
            raise InputError("already in the model", parameter=f"--add {name}")
        model = model + effects[name]
    return model


def _json_text(payload):
    """``payload`` as strict JSON: non-finite numbers become null, never NaN or Infinity."""
    return json.dumps(json_safe(payload), indent=2, allow_nan=False)


def _emit(args, payload, lines):
    print(_json_text(payload) if _wants_json(args) else lines)


def _demo_options(parser):
    parser.add_argument("--out", default="feedaxis-demo", help="output folder (default: feedaxis-demo)")


@command("demo", help="the whole loop on the bundled Liu 2023 case, then the FMUs",
         description="Diagnose, add the missing effect, refit, until the verdict is adequate, "
                     "on the bundled Liu 2023 micro ball screw; write the model, the report "
                     "and the FMUs into --out and check the FMUs reproduce the fitted model.",
         options=_demo_options)
def _cmd_demo(args):
    from . import demo

    check_writable_target(args.out, "folder")
    summary = demo.run_demo(args.out, echo=(lambda line: None) if _wants_json(args) else print)
    if _wants_json(args):
        print(_json_text(summary))


def _fit_options(parser):
    parser.add_argument("cases", nargs="+", metavar="CASE", help=CASE_HELP)
    _add_model_options(parser)
    parser.add_argument("--add", metavar="EFFECT", action="append",
                        help="add an effect by name (repeatable); see `feedaxis effects`")
    parser.add_argument("--out", metavar="M2.toml", help="write the fitted model here")
    _add_correction_option(parser)


@command("fit", help="fit a model's effects to one or several cases",
         description="Bounded least squares over every parameter of the model's effects "
                     "(and of --add EFFECT), jointly over all CASE folders, on the samples "
                     "the effects act on (positioning.csv or tracking.csv); the parameters "
                     "entering linearly are solved exactly (variable projection). Prints "
                     "each parameter with its standard uncertainty and the parameters the "
                     "data cannot determine.",
         options=_fit_options)
def _cmd_fit(args):
    from .fit import check_available, evaluate, fit_with_artefacts
    from .measurement import kinds_for
    from .plausibility import warn_implausible_fit

    if args.out:
        check_writable_target(args.out)
    cases = _read_cases(args, args.cases)
    effects = _effects(args, cases)
    starting = _starting_model(args, effects)
    model = _with_added(starting, args.add, effects)
    results = []
    for kind in kinds_for(cases, model):
        check_available(model, cases, kind)
        before_um = evaluate(starting, cases, kind).rms_um  # its residual not kept: 8 B a row
        with _progress("fitting", " evaluations") as tick:
            result = fit_with_artefacts(model, cases, progress=tick, kind=kind)
        alone = evaluate(result.fitted_model(), cases, kind)
        warn_implausible_fit(result.fitted_model())
        results.append((before_um, result, alone.rms_um))
    if args.out:
        write_atomically(args.out, results[0][1].fitted_model().to_toml())
    _emit_each(args, [(result.kind, _fit_payload(before_um, result, alone_um),
                       text.fit_lines(result, before_um, args.out, alone_um))
                      for before_um, result, alone_um in results])


def _read_cases(args, folders):
    """The case folders read (corrected to 20 °C when asked), under a progress bar: a
    case of 10^7 rows takes seconds to read."""
    with _progress("reading", " cases") as tick:
        cases = []
        for folder in folders:
            cases.append(corrected_case(read_case(folder), args.correct_to_20C))
            tick()
    return cases


def _fit_payload(before_um, result, alone_um):
    """The --json of a fit: the model's parameters, and the measurement's artefacts apart;
    ``rms_after_um`` with the artefacts fitted beside the model, ``rms_model_alone_um`` the
    saved model on every sample (what compare gives)."""
    fitted = result.fitted_model()
    keys = set(fitted.parameter_keys)
    return {"rms_before_um": before_um, "rms_after_um": result.rms_um,
            "rms_model_alone_um": alone_um,
            "effects": list(fitted.names), "params": fitted.values,
            "uncertainties": {name: result.uncertainties[name] for name in fitted.names},
            "undetermined": {k: v for k, v in result.undetermined.items() if k in keys},
            "artefacts": fitted.record.artefacts, "statistics": vars(result.statistics)}


def _case_and_model(args):
    """(effects, case (corrected to 20 °C when asked), starting model, the kinds of
    measurement to compare it with)."""
    from .measurement import kinds_for

    case, = _read_cases(args, [args.case])
    effects = _effects(args, [case])
    model = _starting_model(args, effects)
    return effects, case, model, kinds_for([case], model)


def _emit_each(args, outputs):
    """Print [(kind, payload, text)], one per kind of measurement compared: one output as
    it is (its JSON with ``measurement``), several under ``measurements``, each headed."""
    from .kinds import kind as kind_named

    payloads = [{**payload, "measurement": kind} for kind, payload, _ in outputs]
    if len(outputs) == 1:
        _emit(args, payloads[0], outputs[0][2])
        return
    _emit(args, {"measurements": payloads},
          "\n\n".join(f"== {kind} ({kind_named(kind).file}) ==\n{lines}"
                       for kind, _, lines in outputs))


def _diagnose_options(parser):
    parser.add_argument("case", metavar="CASE", help=CASE_HELP)
    _add_model_options(parser)
    _add_correction_option(parser)


@command("diagnose", help="where the model fails and which effect is missing",
         description="Refit the model as fit does (outliers named by row and kept out, a "
                     "drift along the test fitted beside the effects), then fit each missing "
                     "effect on top and judge it by an F test against the noise the samples "
                     "support: the pure error of repeated samples (or of the + and - readings "
                     "at each target in one pass each way), the residual mean square where "
                     "there are no replicates, the noise power at the term's frequencies "
                     "where the residual is serially correlated (Ljung-Box, AR model), or "
                     "the effective sample count of a tracking trace. Stepwise: the smallest "
                     "p-value is accepted below a family-wise error rate of 0.001 (Bonferroni "
                     "over the stages and the effects tried). Then describe structure no "
                     "effect explains (a periodic error, a trend, a reversal, a drift, a "
                     "constant force; a lack of fit left) under the same policy, and give a "
                     "verdict: adequate, missing_effect, unexplained, or undetermined (the "
                     "samples cannot tell noise from structure; the reason is given). The "
                     "noise line and the test line name the same noise model. A case with "
                     "positioning.csv and tracking.csv is diagnosed on the samples the "
                     "model's effects act on, or on each in turn with an empty model.",
         options=_diagnose_options)
def _cmd_diagnose(args):
    from .diagnose import diagnose

    effects, case, model, kinds = _case_and_model(args)
    outputs = []
    for kind in kinds:
        with _progress(f"diagnosing {kind}", " fits") as tick:
            diagnosis = diagnose(case, model, effects, progress=tick, kind=kind)
        outputs.append((kind, diagnosis.to_json(), text.diagnosis_lines(diagnosis)))
    _emit_each(args, outputs)


def _add_standard_option(parser):
    from .standards import DEFAULT, NAMES, parse

    parser.add_argument("--standard", type=parse, default=DEFAULT, metavar="NAME",
                        help=f"the standard and edition of the positioning figures (default "
                             f"{DEFAULT}; 'all': side by side): {', '.join(NAMES)}. See "
                             "docs/standards.md")


def _compare_options(parser):
    parser.add_argument("case", metavar="CASE", help=CASE_HELP)
    _add_model_options(parser, "model (TOML) as fitted; without it the model is empty")
    _add_correction_option(parser)
    _add_standard_option(parser)


@command("compare", help="the measurement's figures: measured against the model",
         description="Positioning: ISO 230-2 accuracy, repeatability, reversal and systematic "
                     "deviation of the measured runs and of what is left after the model, "
                     "side by side (--standard: another standard's, or all; a thermal case's "
                     "ISO 230-3 figures, measured, predicted and compensated). Tracking: "
                     "the maximum and RMS tracking error (as Anang et al. 2017 report them) "
                     "after the first second, measured and predicted.",
         options=_compare_options)
def _cmd_compare(args):
    from .analysis import compare

    outputs = []
    _, case, model, kinds = _case_and_model(args)
    with _progress("comparing", " steps") as tick:
        for kind in kinds:
            comparison = compare(case, model, kind, args.standard, progress=tick)
            outputs.append((kind, comparison, text.comparison_lines(comparison)))
    _emit_each(args, outputs)


def _report_options(parser):
    parser.add_argument("case", metavar="CASE", help=CASE_HELP)
    _add_model_options(parser, "fitted model (TOML); without it the model is empty")
    parser.add_argument("--out", metavar="REPORT.html", help="default: <case>-report.html")
    _add_correction_option(parser)
    _add_standard_option(parser)


@command("report", help="self-contained HTML page with the plots",
         description="The diagnosis, the measurement against the model (drawn between the "
                     "targets too), the residual and its spectrum, each effect's contribution, "
                     "the error ladder, the figures of compare with the ISO 230-2 deviation "
                     "plot, and the model's parameters, on one self-contained HTML page (a "
                     "case with both measurements: both).",
         options=_report_options)
def _cmd_report(args):
    from .analysis import analyse
    from .report import write_report

    effects, case, model, kinds = _case_and_model(args)
    out = Path(args.out or f"{Path(args.case).resolve().name}-report.html")
    check_writable_target(out)
    analyses = []
    for kind in kinds:
        with _progress(f"analysing {kind}", " steps") as tick:
            analyses.append(analyse(case, model, effects, kind=kind, progress=tick,
                                    standard=args.standard))
    with _progress("writing the report", " pages"):
        write_report(analyses, out)
    _emit(args, {"report": str(out)}, f"report: {out}")


def _compensate_options(parser):
    parser.add_argument("case", metavar="CASE", help=CASE_HELP)
    _add_model_options(parser, "fitted model with thermal_screw (TOML)", required=True)
    parser.add_argument("--out", metavar="COMPENSATION.csv",
                        help="write per sample: time_s, target_mm, direction, measured_um, "
                             "thermal_error_um, correction_um, left_um")


@command("compensate", help="thermal correction at each sample and the error it leaves",
         description="Apply the model's thermal effects (thermal_screw, ambient_expansion) as "
                     "a compensation to a thermal case, as Rong et al. 2023 §5.2: the thermal error is "
                     "each target's drift from its first visit; print its max and RMS before "
                     "and after, per target and over time.",
         options=_compensate_options)
def _cmd_compensate(args):
    from .case import csv_text
    from .compensate import compensate

    if args.out:
        check_writable_target(args.out)
    case = read_case(args.case)
    result = compensate(case, load_model(args.model, _effects(args)))
    if args.out:
        write_atomically(args.out, csv_text(result.columns()))
    _emit(args, result.to_json(), text.compensation_lines(result, args.out))


def _import_options(parser):
    parser.add_argument("file", metavar="FILE", help="the export: .rtl or .csv")
    parser.add_argument("--axis", required=True, metavar="AXIS.toml",
                        help="axis.toml (or a case folder holding one) describing the axis")
    parser.add_argument("--out", required=True, metavar="CASE", help="case folder to create")
    parser.add_argument("--map", action="append", metavar="TARGET=SOURCE[*SCALE]",
                        help="a drive trace (CSV): tracking.csv's column TARGET from the "
                             "export's column SOURCE times SCALE (repeatable), e.g. "
                             "actual_mm=Pos_act*0.001; TARGET: time_s or sample, reference_mm, "
                             "actual_mm, control_V, disturbance_N")
    parser.add_argument("--sample-time-s", type=float, metavar="S",
                        help="with --map sample=...: the drive's sampling time (s)")
    parser.add_argument("--columns", metavar="MAP", type=column_map,
                        help="a .csv whose headers are not recognised: "
                             "'HEADER=target:UNIT,HEADER=run1+:UNIT,HEADER=run1-:UNIT,...' "
                             "(units mm, m, µm, nm, in; a deviation defaults to µm)")


@command("import", help="laser export (Renishaw .rtl, wide CSV) or a drive trace (--map) "
                        "-> case folder",
         formatter_class=argparse.RawDescriptionHelpFormatter,
         description="Read a laser-interferometer export and write a case folder (case format "
                     "1.2, docs/case-format.md: AXIS.toml + positioning.csv), all files or none. "
                     "Says which metadata the case format cannot hold.",
         epilog="Formats, by extension:\n"
                "  .rtl  Renishaw linear data file (sections HEADER::, TARGET DATA::, RUNS::,\n"
                "        DEVIATIONS::, ...): odd runs approach in +, even runs in -.\n"
                "  .csv  wide spreadsheet layout, one row per target:\n"
                "          target_mm,run1+,run1-,run2+,run2-\n"
                "          0.000,1.2,3.4,1.1,3.6\n"
                "          50.012,0.8,2.9,,3.0\n"
                "        target_mm first (mm); then one column per run and direction,\n"
                "        run<N>+ / run<N>- (or run<N>_up / run<N>_down), the deviation\n"
                "        measured - target in µm; an empty cell = not measured; '#' comment\n"
                "        lines; ';'- or tab-separated files may use a decimal comma.\n"
                "        Vendor headers with units are recognised: 'Target (mm)',\n"
                "        'Run 1 Fwd (µm)', 'Run 1 Rev (µm)' (fwd/forward/up, rev/reverse/\n"
                "        bwd/backward/down; units mm, m, µm, nm, in); any other layout\n"
                "        is mapped with --columns.\n"
                "See docs/compensation-tables.md and docs/case-format.md.",
         options=_import_options)
def _cmd_import(args):
    if args.map:
        return _import_drive_trace(args)
    from .importers import import_case

    folder, measurement, dropped = import_case(args.file, args.axis, args.out, args.columns)
    directions = sorted({int(d) for d in measurement.direction}, reverse=True)
    payload = {"case": str(folder), "samples": int(measurement.error_um.size),
               "targets": int(len(set(measurement.target_mm))),
               "runs": int(measurement.run.max()), "directions": directions,
               "name": read_case(folder).name, "dropped": dropped,
               **{column: None if values is None else [float(values.min()), float(values.max())]
                  for column, values in (("ambient_C", measurement.ambient_C),
                                         ("material_C", measurement.material_C))},
               "expansion_per_K": measurement.expansion_per_K}
    lines = [f"{folder}: {payload['samples']} samples, {payload['targets']} targets, "
             f"{payload['runs']} runs, directions {', '.join(f'{d:+d}' for d in directions)}"]
    for column, what in (("ambient_C", "air"), ("material_C", "material")):
        if payload[column]:
            lines.append(f"  kept: the {what} temperature as positioning.csv {column}, "
                         + " to ".join(f"{t:g}" for t in sorted(set(payload[column]))) + " °C")
    if payload["expansion_per_K"] is not None and "ENVIRONMENT.EXP COEFF" not in dropped:
        lines.append(f"  kept: the expansion coefficient as [screw] expansion_per_K = "
                     f"{payload['expansion_per_K']:g} /K")
    lines += [f"  dropped (the case format has no place for it): {key} = {value}"
              for key, value in dropped.items()]
    _emit(args, payload, "\n".join(lines))


def _import_drive_trace(args):
    from .importers import import_drive_trace
    from .importers.drive_trace import parse_map

    if args.sample_time_s is not None and not 0.0 < args.sample_time_s < math.inf:
        raise InputError("must be a finite time > 0 (s)", parameter="--sample-time-s")
    folder, columns, dropped = import_drive_trace(args.file, args.axis, args.out,
                                                  parse_map(args.map), args.sample_time_s)
    payload = {"case": str(folder), "samples": int(columns["time_s"].size),
               "columns": list(columns), "dropped": dropped}
    lines = [f"{folder}: {payload['samples']} samples of a drive trace, tracking.csv columns "
             f"{', '.join(columns)}"]
    lines += [f"  dropped: {column}: {why}" for column, why in dropped.items()]
    _emit(args, payload, "\n".join(lines))
def _positive_tolerance(text):
    """``--tolerance-um``: a number > 0 (µm)."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0 < value < float("inf"):
        raise InputError(f"expected a tolerance in µm > 0, got {text!r}",
                         parameter="--tolerance-um")
    return value


def _comp_table_options(parser):
    parser.add_argument("case", metavar="CASE", help=CASE_HELP)
    _add_model_options(parser, "fitted model (TOML); needed unless --from-measurement")
    parser.add_argument("--controller", required=True, choices=list(CONTROLLERS),
                        help="the controller whose file, unit and sign convention to write")
    parser.add_argument("--out", required=True, metavar="FILE",
                        help="the file to write" + "".join(
                            f" ({c.name}: {c.out_note})" for c in CONTROLLERS.values()
                            if c.out_note))
    parser.add_argument("--spacing-mm", type=float, metavar="S",
                        help="distance between table points (default from the model: the "
                             "fewest points that reproduce it within --tolerance-um under the "
                             "controller's grid rules; with --from-measurement the targets)")
    parser.add_argument("--tolerance-um", type=_positive_tolerance, metavar="T",
                        default=TABLE_TOLERANCE_UM,
                        help=f"how closely the model's table must follow the model between "
                             f"its points (default {TABLE_TOLERANCE_UM:g} µm)")
    parser.add_argument("--from-measurement", action="store_true",
                        help="the table from the measured means at the targets, not the model")
    parser.add_argument("--circle-axis", metavar="NAME",
                        help="a circular case: the axis whose table to write (X, Y, ...); the "
                             "circle expected after it is verified")
    parser.add_argument("--axis-id", metavar="ID",
                        help="axis name in the file (" + ", ".join(
                            f"{c.name} {c.axis_note}" for c in CONTROLLERS.values()
                            if c.axis_note) + ": the defaults)")
    parser.add_argument("--force", action="store_true",
                        help="write the table even when it is refused (it had to leave out "
                             "effects the data cannot determine, or it is expected to raise A, "
                             "E or the error between the targets), with warnings saying what "
                             "it risks")
    _add_correction_option(parser)


@command("comp-table", help="pitch-error compensation table for a CNC controller",
         description=f"Write the table a controller loads ({', '.join(CONTROLLERS)}) "
                     "from the fitted model: lead, eccentricity, "
                     "motor and sag in both directions, backlash as a direction-dependent "
                     "table, thermal effects never (a fixed table cannot follow them). With "
                     "--from-measurement: the classical table of the measured means. Then "
                     "read the file back as the controller does and print the ISO 230-2 "
                     "figures expected after it on the measured case, next to those before, "
                     "with a warning when a table cannot help. A table is refused (exit 2, "
                     "nothing written) when it would have to use an effect the data cannot "
                     "determine or is expected to make the axis worse; --force writes it "
                     "anyway. See docs/compensation-tables.md.",
         options=_comp_table_options)
def _cmd_comp_table(args):
    from .comptable import check_case, comp_table, summary_lines

    case = read_case(args.case)
    kind_table = _kind_part(case, "comp_table")
    if kind_table is not None:
        return _kind_comp_table(args, case, kind_table)
    case = check_case(case)
    case = corrected_case(case, args.correct_to_20C)
    if not (args.model or args.from_measurement):
        raise InputError("give the fitted model (--model M.toml) or --from-measurement",
                         parameter="--model")
    model = load_model(args.model, _effects(args)) if args.model else Model()
    files, report = comp_table(case, model, args.controller, args.out, args.spacing_mm,
                               args.from_measurement, args.axis_id, args.force,
                               args.tolerance_um)
    refuse_overwriting_inputs({path: "--out" for path in files}, _inputs(args))
    for path, content in files.items():
        write_atomically(path, content)
    _emit(args, report, summary_lines(report))


def _kind_part(case, name):
    """The part ``name`` of the first kind of measurement ``case`` holds that has one."""
    from .kinds import kind, part

    return next((found for found in (part(kind(held), name) for held in case.samples)
                 if found), None)


def _kind_comp_table(args, case, kind_table):
    """comp-table on a case whose kind writes its own tables (a circular test: one axis's
    table from the fitted model, ``--circle-axis``)."""
    from .comptable import summary_lines

    if not args.model or args.from_measurement:
        raise InputError("a table from this case comes from the fitted model (--model "
                         "M.toml); it has no measured means per position",
                         parameter="--model")
    model = load_model(args.model, _effects(args, [case]))
    files, report = kind_table(case, model, args.controller, args.out, args.circle_axis,
                               args.spacing_mm, args.axis_id, args.force)
    for path, content in files.items():
        write_atomically(path, content)
    _emit(args, report, summary_lines(report))


def _uncertainty_options(parser):
    from .uncertainty.engine import DEFAULT_TRIALS

    parser.add_argument("case", metavar="CASE", help="case folder with positioning.csv")
    _add_model_options(parser, "fitted model (TOML): refitted on the case, then its "
                               "parameters and compensation table get their uncertainty too")
    parser.add_argument("--budget", metavar="BUDGET.toml",
                        help="the uncertainty budget (ISO 230-2 Annex A): the contributions "
                             "it changes, each with its distribution; the others keep the "
                             "defaults of docs/uncertainty.md")
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--trials", type=int, default=DEFAULT_TRIALS, metavar="N",
                      help=f"Monte Carlo trials (default {DEFAULT_TRIALS}: JCGM 101 §7.2)")
    size.add_argument("--tolerance-um", type=float, metavar="T",
                      help="adaptive instead (JCGM 101 §7.9): blocks of 10^4 trials until "
                           "every figure's mean, u and interval ends are stable to T µm")
    parser.add_argument("--seed", type=int, metavar="S",
                        help="random seed: the same seed gives the same intervals (default: "
                             "a fresh one, printed)")
    _add_correction_option(parser)
    parser.add_argument("--html", metavar="PAGE.html",
                        help="also write the results as a page with histograms")
    _add_standard_option(parser)


@command("uncertainty", help="Monte Carlo uncertainty of the ISO 230-2 figures (JCGM 101)",
         description="The measurement uncertainty of the ISO 230-2 figures (A, E, M, R, B, "
                     "B̄ per direction), of the fitted model's parameters and of the "
                     "compensation table's values, by the Monte Carlo method of JCGM 101 "
                     "over a budget in the structure of ISO 230-2 Annex A (laser "
                     "calibration, temperature and expansion coefficient of the 20 °C "
                     "correction, misalignment, set-up/Abbe, EVE) with the repeatability "
                     "from the case's own runs: 95 % coverage intervals (symmetric and "
                     "shortest), standard uncertainties and each input's share. "
                     "--standard: another standard's figures, or ISO 230-3's of a thermal "
                     "case, each reading then scattering on its own (docs/standards.md). See "
                     "docs/uncertainty.md.",
         options=_uncertainty_options)
def _cmd_uncertainty(args):
    from tqdm import tqdm

    from .uncertainty.budget import default_budget, read_budget
    from .uncertainty.evaluation import evaluate
    from .uncertainty.text import uncertainty_lines

    if args.html:
        check_writable_target(args.html)
    case = read_case(args.case)
    model = load_model(args.model, _effects(args)) if args.model else None
    budget = read_budget(args.budget) if args.budget else default_budget()
    with tqdm(desc="Monte Carlo (the trials, then each input's share)", unit="run",
              unit_scale=True, delay=1.0, leave=False, file=sys.stderr, disable=None) as bar:
        def tick(trials, planned):
            bar.total = planned
            bar.update(trials)

        result = evaluate(case, model, budget, args.trials, args.tolerance_um, args.seed,
                          args.correct_to_20C, progress=tick, standard=args.standard)
    payload = result.to_json()
    if args.html:
        from .uncertainty.page import write_page

        payload["html"] = str(write_page(result, args.html))
    _emit(args, payload, uncertainty_lines(result)
          + (f"\npage: {args.html}" if args.html else ""))


def _effects_options(parser):
    parser.add_argument("--effects", metavar="F.py", action="append", help="your own effects file")


@command("effects", help="list the effect catalog (and your own)",
         description="Each effect's meaning, parameters and FMU.",
         options=_effects_options)
def _cmd_effects(args):
    effects = _effects(args)
    payload = {name: {"meaning": e.meaning, "fmu": e.fmu,
                      "parameters": {p.name: {"unit": p.unit, "lower": p.lower, "upper": p.upper,
                                              "meaning": p.meaning} for p in e.parameters}}
               for name, e in effects.items()}
    _emit(args, payload, text.effect_lines(effects))


STANDALONE_HELP = ("each FMU carries the Python its physics needs (about 21 MB each), for FMI "
                   "hosts on machines without Python (docs/fmu-hosts.md); without it the FMUs "
                   "are small and need this machine's Python")


FMI_HELP = ("FMI version of the FMUs: 2 (FMI 2.0, default) or 3 (FMI 3.0 co-simulation, the "
            "same physics and results; docs/fmus.md)")


def _build_fmus_options(parser):
    parser.add_argument("--out", default="build/fmus", help="FMU folder (default: build/fmus)")
    parser.add_argument("--standalone", action="store_true", help=STANDALONE_HELP)
    parser.add_argument("--fmi", type=int, choices=(2, 3), default=2, help=FMI_HELP)


@command("build-fmus", help="build the five FMUs",
         description="Build NpidServo, StepperError, GeometricError, ThermalScrew (the axis) "
                     "and CircleInterpolator (a machine's circle) into --out.",
         options=_build_fmus_options)
def _cmd_build_fmus(args):
    from . import fmu_build

    check_writable_target(args.out, "folder")
    with _progress("building FMUs", "FMU") as tick, _standalone_errors():
        paths = fmu_build.build_fmus(args.out, standalone=args.standalone, progress=tick,
                                     fmi=args.fmi)
    _emit(args, [str(p) for p in paths], "\n".join(str(p) for p in paths))


@contextmanager
def _standalone_errors():
    """A machine that cannot build standalone FMUs: one clear error naming the option."""
    from .fmu_standalone import StandaloneUnavailable

    try:
        yield
    except StandaloneUnavailable as error:
        raise InputError(f"cannot build standalone FMUs here: {error}",
                         parameter="--standalone") from None


def _axis_system(args):
    """The default axis from the command's axis options (--step-ms, --thermal-step-s,
    --model/--axis, --set): :func:`feedaxis.cosim.system.axis_from_options`."""
    from .cosim.system import axis_from_options

    return axis_from_options(args.step_ms, getattr(args, "thermal_step_s", None), args.model,
                             args.axis, args.set, _effects(args))


def _fmu_paths(args):
    from .cosim.fmu_cache import fmu_paths

    with _standalone_errors():
        return fmu_paths(args.fmus, getattr(args, "standalone", False), getattr(args, "fmi", None))


@contextmanager
def _counter_progress(label, unit, unit_scale=False):
    """A tqdm bar of ``progress(done, total)`` calls on stderr, shown after a second."""
    from tqdm import tqdm

    with tqdm(desc=label, unit=unit, unit_scale=unit_scale, delay=1.0, leave=False,
              file=sys.stderr, disable=None) as bar:
        def update(done, total):
            bar.total = total
            bar.update(done - bar.n)

        yield update


def _simulate(args, run, system=None):
    """Run one scenario into a new case folder (on ``system``, default the axis of the
    axis options); Ctrl-C keeps what was computed."""
    from .cosim.master import Master
    from .cosim.scenarios.base import check_axis_ranges

    if Path(args.out).exists():
        raise InputError("already exists; choose a new case folder", path=args.out)
    check_writable_target(args.out, "folder")
    if system is None:
        system, paths = _checked_axis(args)
    else:
        from .cosim.physics_check import check_parameters

        paths = _fmu_paths(args)
        check_parameters(system, paths)
    check_axis_ranges(system)
    with Master(system, paths) as master:
        with _counter_progress("simulating", "step", True) as progress:
            return run(master, progress)


def _simulate_options(parser):
    _scenario_parsers(parser, "case folder to create (must not exist)", _noise_options)


def _noise_options(sub):
    sub.add_argument("--noise-um", type=float, default=0.0,
                     help="white Gaussian measurement noise added to what the case records "
                          "as measured, standard deviation in µm (default 0: the simulated "
                          "axis exactly)")
    sub.add_argument("--seed", type=int, default=0, help="seed of the noise (default 0)")


def _noise(args):
    from .cosim.scenarios import MeasurementNoise

    return MeasurementNoise(args.noise_um, args.seed) if args.noise_um else None


def _scenario_parsers(parser, out_help, more_options=None, handler=None):
    """One subparser per scenario of the registered kinds (:func:`feedaxis.kinds.scenarios`):
    its options, OUT, ``more_options``, the axis options; run by ``handler`` (default:
    :func:`_cmd_simulate`), a sweep's (``handler`` given) only where the scenario sweeps."""
    from .kinds import scenarios as registered_scenarios

    scenarios = parser.add_subparsers(dest="scenario", required=True, metavar="SCENARIO")
    for name, scenario in registered_scenarios().items():
        if handler and not scenario.sweeps:
            continue
        sub = scenarios.add_parser(name, help=scenario.help, description=scenario.description)
        scenario.options(sub)
        sub.add_argument("out", metavar="OUT", help=out_help)
        if more_options:
            more_options(sub)
        _add_axis_options(sub)
        _add_common_options(sub)
        sub.set_defaults(handler=handler or _cmd_simulate, run_scenario=scenario)


def _cmd_simulate(args):
    scenario = args.run_scenario
    keywords = scenario.arguments(args)
    system = scenario.system(args) if scenario.system else None
    summary = _simulate(args, lambda master, progress: scenario.simulate(
        args.out, master, progress=progress, noise=_noise(args), **keywords), system)
    _emit(args, summary, scenario.line(args, summary))


# the scenarios of the kinds carry the handlers
command_group("simulate", help="run a scenario on the co-simulated axis, write a case folder",
              description="Co-simulate the four FMUs as one axis (the fmpy master) through a "
                          "scenario and write the result as a measurement case (docs/case-format.md), "
                          "ready for fit, diagnose and compare. iso230 and thermal run the servo "
                          "with a type-1 plant (NpidServo.plant_stiffness_per_s2 = 0: Anang et al. 2017's "
                          "193.3 leaves a static error of target/364); --set overrides it. Ctrl-C "
                          "stops and keeps what was computed.",
              options=_simulate_options)


def _checked_axis(args):
    """The axis system (the machine of two axes with ``--machine``) and FMU paths, its
    parameter values accepted by every FMU."""
    from .cosim.physics_check import check_parameters

    system, paths = _machine_or_axis(args), _fmu_paths(args)
    check_parameters(system, paths)
    return system, paths


def _machine_or_axis(args):
    """The machine of ``--machine`` (two axes, :mod:`feedaxis.cosim.machine`) driven round
    its circle by the CircleInterpolator FMU (:func:`_machine_path`), else the axis."""
    if getattr(args, "machine", None) is None:
        return _axis_system(args)
    from .cosim.machine import with_interpolator

    return with_interpolator(*_machine_path(args))


def _machine_path(args):
    """(the machine system of ``--machine``, the commanded circle of its direction)."""
    from .cosim.circular import DIRECTIONS
    from .cosim.machine import circular_machine
    from .physics.circle import CircleInterpolator

    system, circle = circular_machine(args.machine or None,
                                      squareness_urad=args.squareness_urad,
                                      step_ms=args.step_ms, thermal_step_s=args.thermal_step_s,
                                      set_items=args.set, model_path=args.model)
    return system, CircleInterpolator(circle["radius_mm"], circle["feed_mm_min"],
                                      circle["center_mm"], DIRECTIONS[args.direction][0])


def _export_ssp_options(parser):
    parser.add_argument("out", metavar="OUT.ssp", help="SSP file to write")
    parser.add_argument("--machine", nargs="?", const="", metavar="AXIS",
                        help="the machine of two axes instead of one axis (components "
                             "X_NpidServo, ...), driven round its circle by the "
                             "CircleInterpolator FMU: alone the default axes X and Y, or those "
                             "of the axis.toml (or case folder) of a circular case")
    parser.add_argument("--squareness-urad", type=float, default=0.0,
                        help="with --machine: the second axis out of square with the first "
                             "(µrad), a term of the first axis's table position (printed)")
    parser.add_argument("--direction", choices=("ccw", "cw"), default="ccw",
                        help="with --machine: the direction the CircleInterpolator FMU "
                             "commands the circle in (default ccw)")
    parser.add_argument("--standalone", action="store_true", help=STANDALONE_HELP)
    parser.add_argument("--fmi", type=int, choices=(2, 3), default=2, help=FMI_HELP)
    parser.add_argument("--stop-time", type=float, metavar="S",
                        help="DefaultExperiment stopTime in s (default 1; with --machine the "
                             "circle's lead-in, turn and lead-out)")
    parser.add_argument("--osp-step-hints", action="store_true",
                        help="add OSP's per-component step sizes (libcosim runs the thermal screw "
                             "at its own step); OMSimulator 3.0 refuses such a file")
    _add_axis_options(parser)


@command("export-ssp", help="the axis as an SSP file for other FMI system simulators",
         description="Write OUT.ssp: SystemStructure.ssd (components, connections, step "
                     "sizes), resources/<Component>.ssv (parameter values) and the FMUs. "
                     "Runs in fmpy.ssp.simulate_ssp, OSP libcosim (libcosimpy), OMSimulator and "
                     "ecos; see README.",
         options=_export_ssp_options)
def _cmd_export_ssp(args):
    from .cosim.ssp import export_ssp, open_inputs

    check_writable_target(args.out)
    system, paths = _checked_axis(args)
    stop_time = args.stop_time
    if stop_time is None:
        stop_time = 1.0 if args.machine is None else _circle_stop_s(system)
    path = export_ssp(args.out, system, paths, stop_time, args.osp_step_hints)
    unconnected = [{"input": connector, "unit": variable.unit, "start": variable.start,
                    "meaning": variable.description}
                   for connector, variable in open_inputs(system)]
    payload = {"ssp": str(path), "open_inputs": unconnected}
    lines = (f"{path}: SystemStructure.ssd, a parameter-values file (.ssv) per component and its "
             f"{len({c.fmu for c in system.components})} {'standalone ' if args.standalone else ''}"
             "FMUs\n"
             "open inputs (unconnected: drive them from the importing tool, else they keep their "
             "start values; position_ref_mm at 0 is a standing axis):\n"
             + "\n".join(f"  {i['input']} = {i['start']:g} {i['unit']} ({i['meaning']})"
                         for i in unconnected))
    if args.machine is not None:
        payload["interpolator"] = system.component("CircleInterpolator").parameters
        lines += ("\nCircleInterpolator drives both servos' position_ref_mm, one macro step "
                  "ahead (ahead_s) for hosts that step Jacobi: "
                  + ", ".join(f"{k} = {v:g}" for k, v in payload["interpolator"].items())
                  + "\nposition connectors count from the first reference (origin_first_mm, "
                    "origin_second_mm; each axis FMU's position_offset_mm): 0 at the start in "
                    "every host")
        payload["outputs"] = {o.variable.name: o.formula() for o in system.outputs}
        lines += ("\nthe machine's table positions (mm) from the component outputs:\n"
                  + "\n".join(f"  {name} = {formula}"
                              for name, formula in payload["outputs"].items()))
    _emit(args, payload, lines)



def _circle_stop_s(system):
    """The macro steps (s) that cover the machine's circle with its arcs."""
    from .cosim.circular import path_stop_s
    from .cosim.machine import interpolator_path

    return float(path_stop_s(interpolator_path(system), system.macro_step_s))


def _export_fmu_options(parser):
    parser.add_argument("out", metavar="OUT.fmu", help="FMU file to write")
    parser.add_argument("--standalone", action="store_true", help=STANDALONE_HELP)
    parser.add_argument("--fmi", type=int, choices=(2, 3), default=2, help=FMI_HELP)
    _add_axis_options(parser, thermal_step=False)


@command("export-fmu", help="the axis as one FMU (fmpy container FMU)",
         description="Wrap the four FMUs in one co-simulation FMU of their FMI version (2.0, "
                     "or 3.0 with --fmi 3) with fmpy's container FMU: inputs position_ref_mm, "
                     "disturbance_N, ambient_C; every component output; the parameter values "
                     "as fixed parameters. All four FMUs step at the container's one step "
                     "(--step-ms), Jacobi: the error FMUs see the servo one step late.",
         options=_export_fmu_options)
def _cmd_export_fmu(args):
    from .cosim.container import export_container_fmu

    check_writable_target(args.out)
    path = export_container_fmu(args.out, *_checked_axis(args))
    _emit(args, {"fmu": str(path)}, f"{path}: the axis as one FMU (fmpy container of the four "
                                    f"FMUs, one {args.step_ms:g} ms step for all)")


def _sweep_options(parser):
    _scenario_parsers(parser, "folder to create (must not exist unless --resume): "
                              "trials.parquet, summary.json, summary.txt, report.html",
                      _add_sweep_options, _cmd_sweep)


def _add_sweep_options(sub):
    sub.add_argument("--vary", metavar="NAME=SPEC", action="append", default=[],
                     help="vary an FMU parameter (repeatable): COMPONENT.PARAMETER= "
                          "grid(a,b,n) | uniform(a,b) | normal(mu,sigma) | "
                          "truncnormal(mu,sigma,lo,hi) | triangular(a,mode,b); "
                          "A.x,B.y=mvnormal([mu1,mu2],[[c11,c12],[c21,c22]]) for a "
                          "correlated normal")
    sub.add_argument("--trials", type=int, metavar="N",
                     help="draws of the sampled specs and of --from-model (each grid "
                          "point gets N); grids alone set their own count")
    sub.add_argument("--seed", type=int, default=0,
                     help="trial k draws from the stream (seed, k) (default 0)")
    sub.add_argument("--from-model", metavar="M.toml",
                     help="draw the model's parameters from the covariance its fit saved "
                          "([fit] table, `feedaxis fit --out`); needs --axis")
    sub.add_argument("--hold-undetermined", action="store_true",
                     help="hold the parameters the fit could not determine at their "
                          "fitted values (without it such a model is refused)")
    sub.add_argument("--workers", type=int, metavar="N",
                     help="local Dask worker processes (default: in this process while "
                          "that is sooner, else one per core; 0 runs in this process)")
    sub.add_argument("--scheduler", metavar="ADDRESS",
                     help="run on the Dask cluster of this scheduler (tcp://host:8786) "
                          "instead of a local one")
    sub.add_argument("--resume", action="store_true",
                     help="run only the trials an interrupted sweep into OUT has not "
                          "finished")


# the scenarios of simulate, each swept by the one handler below
command("sweep", help="many co-simulations of a scenario with varied FMU parameters (Dask)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run a scenario once per trial, each with its own FMU parameter values "
                    "(--vary specs, or a fitted model's parameters drawn from its fit's\n"
                    "covariance with --from-model), on a local Dask cluster, a remote one "
                    "(--scheduler) or in this process\n(--workers 0). Writes OUT/"
                    "trials.parquet (one row per trial: its inputs, the scenario's figures, "
                    "its curve),\nand the summary (quantiles, sensitivities, prediction "
                    "bands) as summary.txt, summary.json and report.html.\nThe file is the "
                    "same whatever runs it. Ctrl-C keeps the finished trials; --resume runs "
                    "the rest. See docs/sweep.md.",
        epilog="examples:\n"
               "  feedaxis sweep iso230 out --vary GeometricError.backlash_um=grid(0,10,11) "
               "--targets 3 --runs 2\n"
               "  feedaxis sweep tracking out --vary NpidServo.friction_N=uniform(0,2) "
               "--trials 200\n"
               "  feedaxis sweep thermal out --duty duty.csv --targets 50,250 --from-model "
               "thermal.toml --axis CASE --trials 500",
        options=_sweep_options)(None)


def _cmd_sweep(args):
    from .cosim.sweep import sweep
    from .cosim.sweep.summary import summary_lines

    with _counter_progress("sweeping", "trial") as progress:
        sweep(args.scenario, args.vary, args.trials, args.seed, args.out,
              from_model=args.from_model, axis=args.axis,
              hold_undetermined=args.hold_undetermined, step_ms=args.step_ms,
              thermal_step_s=args.thermal_step_s, model=args.model, set_items=args.set or (),
              effects=_effects(args), fmus=args.fmus,
              workers=args.workers, scheduler=args.scheduler, resume=args.resume,
              progress=progress, echo=lambda line: print(line, file=sys.stderr),
              **args.run_scenario.arguments(args))
    summary = json.loads((Path(args.out) / "summary.json").read_text())
    _emit(args, summary, summary_lines(summary) + f"\nfiles: {args.out}/trials.parquet, "
                                                  "summary.json, summary.txt, report.html")


def _add_model_options(sub, model_help="starting model (TOML); without it the model is empty",
                       required=False):
    sub.add_argument("--model", metavar="M.toml", help=model_help, required=required)
    sub.add_argument("--effects", metavar="F.py", action="append",
                     help="Python file with your own effects (repeatable); see docs/own-effect.md")


def _add_correction_option(sub):
    sub.add_argument(CORRECTION_OPTION, dest="correct_to_20C", metavar="T", nargs="?",
                     const=MATERIAL, type=temperature_option, help=CORRECTION_HELP)


def _add_axis_options(sub, thermal_step=True):
    sub.add_argument("--step-ms", type=float, default=1.0,
                     help="macro step = servo, motor and geometry step (default 1 ms)")
    if thermal_step:
        sub.add_argument("--thermal-step-s", type=float,
                         help="ThermalScrew step, a whole multiple of the macro step (default "
                              "0.1 s, rounded up to a multiple of the macro step)")
    sub.add_argument("--set", metavar="COMPONENT.PARAMETER=VALUE", action="append",
                     help="parameter value (repeatable), e.g. NpidServo.nonlinear=true")
    _add_model_options(sub, "fitted model (TOML): its FMU parameter values (needs --axis)")
    sub.add_argument("--axis", metavar="AXIS", help="axis.toml or case folder the model was "
                                                    "fitted on")
    sub.add_argument("--fmus", metavar="DIR", help="use the FMUs in DIR (default: built once "
                                                   "into the user cache)")


class _Parser(argparse.ArgumentParser):
    """argparse whose usage errors are :class:`InputError`, so ``--json`` reports them too."""

    def error(self, message):
        self.print_usage(sys.stderr)
        raise InputError(f"{message} (see {self.prog} --help)")


def build_parser(command=None):
    """The argparse parser with every subcommand; with ``command`` only that one's options
    are added (``simulate`` and ``sweep`` load the kinds' scenarios for theirs)."""
    parser = _Parser(
        prog="feedaxis",
        description="Digital twin of a ball-screw feed axis. Compare a model with "
                    "laser-interferometer and thermal-test data, see where it fails, learn "
                    "which physical effect is missing, add it, watch the error fall. The "
                    "model runs as FMI 2.0 FMUs (NpidServo, StepperError, GeometricError, "
                    "ThermalScrew).",
        epilog="Start with `feedaxis demo`. Exit codes: 0 ok, 2 bad input (the message names "
               "the file, row and column or the option), 1 an internal error (a bug: add "
               "--debug for the traceback), 130 interrupted (143 SIGTERM, 129 SIGHUP).")
    parser.add_argument("--version", action="version", version=f"feedaxis {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, parser_kwargs, options, handler in COMMANDS:
        sub = commands.add_parser(name, **parser_kwargs)
        if options and command in (None, name):
            options(sub)
        _add_common_options(sub)
        if handler:
            sub.set_defaults(handler=handler)
    return parser

def _add_common_options(parser):
    """--json and --debug, the one definition for every command and scenario. Left unset
    by default, so ``simulate --json iso230 OUT`` and ``simulate iso230 OUT --json`` agree
    (a subcommand's default would overwrite the option given before it)."""
    parser.add_argument("--json", action="store_true", default=argparse.SUPPRESS,
                           help="print strict JSON on stdout (errors too: error, file, row, column)")
    parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                           help="on an internal error, show the Python traceback")
    parser.add_argument("--follow-links", action="store_true", default=argparse.SUPPRESS,
                        help="read case files that are links to files outside their case "
                             "folder (refused by default: a case received must not reach "
                             "outside itself)")


INPUT_OPTIONS = {"case": "CASE", "cases": "CASE", "file": "FILE", "axis": "--axis",
                 "model": "--model", "effects": "--effects", "budget": "--budget",
                 "duty": "--duty", "from_model": "--from-model", "fmus": "--fmus"}
OUTPUT_OPTIONS = {"out": "--out", "html": "--html"}


def _inputs(args):
    """Every path the command reads: the files and folders its options name, and the case
    files and FMUs inside a folder named."""
    from .case import case_files
    from .fmu_build import FMU_NAMES

    inside = (*case_files(), *(f"{name}.fmu" for name in FMU_NAMES))
    found = []
    for dest in INPUT_OPTIONS:
        value = getattr(args, dest, None)
        for path in map(Path, value if isinstance(value, list) else [value] if value else []):
            found += [path, *(path / name for name in inside if (path / name).exists())]
    return found


def _outputs(args):
    """{path: option} of what the command writes (``report`` without ``--out`` writes
    ``<case>-report.html`` in the working folder, never a case file)."""
    return {getattr(args, dest): option for dest, option in OUTPUT_OPTIONS.items()
            if getattr(args, dest, None)}


def _effects_files(argv):
    """The files of every ``--effects`` in ``argv``, loaded before the parser is built: an
    effects file may register a kind, whose scenarios are subcommands of simulate and sweep."""
    return ([value for option, value in zip(argv, argv[1:]) if option == "--effects"]
            + [item.partition("=")[2] for item in argv if item.startswith("--effects=")])


def _wants_json(args):
    return getattr(args, "json", False)


@contextmanager
def _one_line_warnings():
    """Warnings as ``feedaxis: warning: ...`` lines, without Python's source line."""
    python_format = warnings.formatwarning
    warnings.formatwarning = lambda message, *_, **__: f"feedaxis: warning: {message}\n"
    try:
        yield
    finally:
        warnings.formatwarning = python_format


def main(argv=None):
    """Entry point of the command line; returns the exit code.

    Bad input (:class:`InputError`, a usage error) exits 2 with one message naming where,
    and so does a disk that is full or read-only (naming the file); anything else is a bug:
    exit 1 with one line (``--debug`` re-raises it for the traceback). With ``--json`` the
    message is a JSON object on stdout. Ctrl-C exits 130 with one line (SIGTERM 143,
    SIGHUP 129: :mod:`feedaxis.stop`).
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    wants_json, debug = "--json" in argv, "--debug" in argv
    try:
        from threadpoolctl import threadpool_limits

        available_effects(_effects_files(argv))  # a file's kinds bring their scenarios
        args = build_parser(argv[0] if argv else None).parse_args(argv)
        refuse_overwriting_inputs(_outputs(args), _inputs(args))
        FOLLOW_LINKS.set(getattr(args, "follow_links", False))
        stop.raise_if_swallowed()  # by the start-up's imports
        with _one_line_warnings():
            args.handler(args)
    except KeyboardInterrupt as stopped:  # a scenario's says what it kept, once
        return _interrupted(wants_json, stopped)
    except BrokenPipeError:
        sys.stderr.close()
        return 0
    except InputError as error:
        return fail(wants_json, str(error), 2, error.as_json())
    except OSError as error:
        refused = write_error(error) if error.errno in DISK_STATE_ERRORS else None
        if refused is None:
            return _internal_error(wants_json, debug, error)
        return fail(wants_json, str(refused), 2, refused.as_json())
    except Exception as error:  # a bug: one line, the traceback with --debug
        stopped = stop.interrupt_behind(error)
        if stopped is not None:
            return _interrupted(wants_json, stopped)
        return _internal_error(wants_json, debug, error)
    return 0


def _interrupted(wants_json, stopped):
    """Exit 128 + the stop signal's number with one line (the interrupt's own message where
    it says what was kept)."""
    message = str(stopped)
    return fail(wants_json, stop.described(message if message.startswith("interrupted")
                                           else "interrupted"), stop.exit_code())


def _internal_error(wants_json, debug, error):
    """Exit 1 with one line; ``--debug`` re-raises for the traceback."""
    if debug:
        raise error
    return fail(wants_json, f"internal error (a bug, please report it): "
                            f"{type(error).__name__}: {error}; run the command again with "
                            "--debug to see the traceback", 1)


if __name__ == "__main__":
    sys.exit(main())
