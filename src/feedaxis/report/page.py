"""The self-contained HTML report: tables and PNG plots embedded as data URIs.

One page for every kind of measurement: the header, the diagnosis, the kind's own views,
each effect's contribution, the error ladder, the figures and the model's parameters. It
only formats :class:`~feedaxis.analysis.Analysis` objects: every number comes from them.
"""
from __future__ import annotations

import base64
import html
import re
from datetime import datetime, timezone
from pathlib import Path

from .. import __version__
from ..stats.wording import p_text
from ..text import micro
from ..output import write_atomically
from ..text import repeatability_text
from . import circular, plots
from .compensation_table import compensation_table_html

STYLE = """body{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #ccc;padding:3px 8px;
text-align:left;vertical-align:top}th{background:#f3f3f3}.number{text-align:right}
img{max-width:100%}.verdict{font-size:1.2em;font-weight:bold}"""
# a cell that is one number (a unit or a percent sign may follow): right-aligned
NUMBER_CELL = re.compile(r"[-+−]?(\d[\d,]*\.?\d*|\.\d+)(e[-+]?\d+)?( ?%)?")


def image(png, alt):
    """An embedded PNG."""
    data = base64.b64encode(png).decode("ascii")
    return f'<p><img alt="{html.escape(alt)}" src="data:image/png;base64,{data}"></p>'


def table(header, rows):
    """An HTML table of text cells: a number right-aligned (so digits line up), text
    left-aligned."""
    def cell(tag, text):
        text = str(text)
        align = ' class="number"' if NUMBER_CELL.fullmatch(text) else ""
        return f"<{tag}{align}>{html.escape(text)}</{tag}>"

    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(cell("td", c) for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _parameter_table(model, refit):
    """The model's parameters with the standard uncertainties of ``refit`` (its refit on
    the case: the diagnosis's base)."""
    rows = []
    for e in model.effects:
        for p in e.parameters:
            sigma = refit.uncertainties.get(e.name, {}).get(p.name)
            note = refit.undetermined.get(f"{e.name}.{p.name}", "")
            rows.append((f"{e.name}.{p.name}", f"{model.values[e.name][p.name]:.6g}",
                         note or ("" if sigma is None else f"{sigma:.2g}"), micro(p.unit),
                         p.meaning))
    return table(("parameter", "value", "standard uncertainty", "unit", "meaning"), rows)


def _diagnosis_html(analysis):
    diagnosis, measurement = analysis.diagnosis, analysis.measurement
    location = f"{measurement.location_key.rsplit('_', 1)[0]} ({measurement.location_unit})"
    parts = [f'<p class="verdict">verdict: {diagnosis.verdict}</p>',
             f"<p>residual RMS {diagnosis.rms_um:.4g} µm; noise {diagnosis.noise_um:.3g} µm "
             f"({html.escape(diagnosis.noise_source)})</p>"]
    if diagnosis.undetermined_reason:
        parts.append(f"<p>undetermined: {html.escape(diagnosis.undetermined_reason)}</p>")
    if diagnosis.repeatability:
        parts.append(f"<p>{html.escape(micro(repeatability_text(diagnosis.repeatability)))}</p>")
    if diagnosis.candidates:
        parts.append(table(("missing effect", "RMS after (µm)", "p-value", "meaning", "evidence"),
                           [(c.effect, f"{c.rms_after_um:.4g}", p_text(c.test.p_value),
                             c.meaning, c.evidence) for c in diagnosis.candidates]))
    if diagnosis.unexplained:
        parts.append(table(("unexplained", location, "amplitude (µm)", "evidence"),
                           [(s.kind, "" if s.location is None else f"{s.location:.4g}",
                             f"{s.amplitude_um:.3g}", s.evidence)
                            for s in diagnosis.unexplained]))
    if diagnosis.outlier_rows:
        parts.append(f"<p>outliers kept out of the fit, rows of {measurement.file}: "
                     f"{', '.join(map(str, diagnosis.outlier_rows))}</p>")
    if diagnosis.transient_rows:
        parts.append(f"<p>transients after the motion's start or stop kept out of the fit, "
                     f"rows of {measurement.file}: "
                     f"{', '.join(map(str, diagnosis.transient_rows))}</p>")
    parts.append(f"<p>{html.escape(diagnosis.test_used)}</p>")
    if diagnosis.skipped:
        parts.append(table(("passed over", "why"), diagnosis.skipped.items()))
    return "".join(parts)


def _positioning_views(analysis):
    """Measurement against model, the residual and its spectrum, the thermal compensation
    and the compensation table."""
    case, result, details = analysis.case, analysis.result, analysis.details
    positioning, dense = case.positioning, details.dense
    panels = _residual_panels(positioning, result.residual_um)
    parts = [
        "<h2>Measurement against model</h2>",
        image(plots.measurement_vs_model(positioning.target_mm, result.measured_um,
                                         dense.position_mm, dense.predicted_um,
                                         dense.direction, dense.line, dense.per_run),
              "measurement against model"),
        "<h2>Residual</h2>",
        image(plots.residual_vs_position(positioning.target_mm, result.residual_um,
                                         details.marks), "residual against position"),
    ]
    if details.unresolved:
        parts.append("<p>Not marked, the targets cannot resolve them: " + "; ".join(
            f"{html.escape(name)} ({html.escape(reason)})"
            for name, reason in details.unresolved.items()) + ".</p>")
    if details.spectrum_missing:
        parts.append(f"<p>No spatial spectrum: {html.escape(details.spectrum_missing)}.</p>")
    else:
        parts.append(image(plots.spectrum(details.residual_spectrum, details.measured_spectrum,
                                          details.marks, analysis.diagnosis.unexplained),
                           "spectrum"))
    if panels:
        parts.append(image(plots.residual_against(panels),
                           "residual against time, direction, ambient"))
    return parts + _compensation_html(details.compensation) + compensation_table_html(
        analysis, image, table)


def _positioning_contributions(analysis):
    """Each effect's contribution between the targets, a short period also over a window
    (at the samples when no line joins two targets)."""
    dense = analysis.details.dense
    if not dense.position_mm.size:
        return _sample_contributions(analysis)
    return plots.contributions(dense.position_mm, dense.components, "position (mm)",
                               dense.line, dense.direction, dense.windows)


def _sample_contributions(analysis):
    """Each effect's contribution at the samples, against their coordinate."""
    measurement = analysis.measurement
    return plots.contributions(measurement.coordinate, analysis.components,
                               measurement.coordinate_label)


def _positioning_figures(analysis):
    comparison, details = analysis.comparison, analysis.details
    rows = [(f["name"], f"{f['measured_um']:.4g}", f"{f['residual_um']:.4g}",
             "" if f["explained"] is None else f"{100 * f['explained']:.1f} %")
            for f in comparison["figures"].values()]
    rows.append(("RMS", f"{comparison['rms_measured_um']:.4g}",
                 f"{comparison['rms_residual_um']:.4g}", ""))
    return ["<h2>ISO 230-2 figures</h2>",
            image(plots.iso230_deviation(details.iso_deviation, details.iso_line),
                  "ISO 230-2 deviation"),
            table(("ISO 230-2 figure", "measured (µm)", "residual (µm)", "explained"), rows)]


def _residual_panels(positioning, residual_um):
    panels = []
    if positioning.time_s is not None:
        panels.append(("time (min)", positioning.time_s / 60.0, residual_um))
    if positioning.bidirectional:
        panels.append(("approach direction", positioning.direction, residual_um))
    if positioning.ambient_C is not None:
        panels.append(("ambient (°C)", positioning.ambient_C, residual_um))
    return panels


def _compensation_html(result):
    """Seed 003 Fig. 13 and the before/after figures, for a thermal model on a thermal case."""
    if result is None:
        return []
    summary = result.summary()
    return [
        "<h2>Thermal compensation (seed 003 Fig. 13)</h2>",
        f"<p>The thermal error is each target's drift from its first visit; the correction is "
        f"the model's thermal prediction. Max {summary['max_before_um']:.3g} µm → "
        f"{summary['max_after_um']:.3g} µm ({100 * summary['reduction']:.1f} % less), RMS "
        f"{summary['rms_before_um']:.3g} → {summary['rms_after_um']:.3g} µm.</p>",
        image(plots.thermal_compensation(result.target_mm, result.visit, result.time_s,
                                         result.thermal_error_um, result.left_um),
              "thermal error without and with compensation"),
        table(("target (mm)", "dir", "max before (µm)", "max after (µm)", "RMS before (µm)",
               "RMS after (µm)"),
              [(f"{r['target_mm']:g}", f"{r['direction']:+d}", f"{r['max_before_um']:.3g}",
                f"{r['max_after_um']:.3g}", f"{r['rms_before_um']:.3g}",
                f"{r['rms_after_um']:.3g}") for r in result.by_target()]),
    ]


def _tracking_views(analysis):
    """Seed 002's tracking error, the deviation against time and velocity, the spectrum."""
    measurement, result, details = analysis.measurement, analysis.result, analysis.details
    comparison = analysis.comparison
    maximum, rms = comparison["max_tracking_error_mm"], comparison["rms_tracking_error_mm"]
    frequency_hz, amplitude_um = details.residual_spectrum
    return [
        "<h2>Tracking error (seed 002)</h2>",
        table(("after the first second", "measured (mm)", "predicted (mm)"),
              [("max tracking error", f"{maximum['measured']:.5f}", f"{maximum['predicted']:.5f}"),
               ("RMS tracking error", f"{rms['measured']:.5f}", f"{rms['predicted']:.5f}")]),
        image(plots.error_against_time(measurement.time_s, result.measured_um,
                                       result.measured_um - result.residual_um,
                                       details.reversals_s), "tracking deviation against time"),
        image(plots.error_against_velocity(details.velocity_mm_s, result.measured_um,
                                           result.residual_um),
              "tracking deviation against velocity"),
        "<h2>Residual spectrum</h2>",
        image(plots.frequency_spectrum(frequency_hz, amplitude_um,
                                       analysis.diagnosis.unexplained), "residual spectrum"),
    ]


# per kind: its views, its figures, its contributions plot
VIEWS = {"positioning": (_positioning_views, _positioning_figures, _positioning_contributions),
         "tracking": (_tracking_views, lambda analysis: [], _sample_contributions),
         "circular": (circular.views, circular.figures, _sample_contributions)}


def _sections(analysis):
    """The page's sections for one analysis."""
    views, figures, contributions = VIEWS[analysis.kind]
    measurement, result, model = analysis.measurement, analysis.result, analysis.model
    steps = analysis.ladder
    return [
        f"<h2>{analysis.kind.capitalize()} ({measurement.file})</h2>",
        f"<p>{html.escape(measurement.describe())}; model: "
        f"{html.escape(' + '.join(model.names) or '(no effect: ' + measurement.reference_label + ')')}"
        f"; residual RMS {result.rms_um:.4g} µm of {result.statistics.rms_before_um:.4g} µm "
        f"measured (R² {result.statistics.r2:.4f})</p>",
        "<h2>Diagnosis</h2>", _diagnosis_html(analysis),
        *views(analysis),
        "<h2>Each effect's contribution</h2>",
        image(contributions(analysis), "contributions") if model.effects
        else "<p>(no effect in the model)</p>",
        "<h2>Error ladder</h2>", image(plots.ladder(steps, analysis.diagnosis.noise_um),
                                       "error ladder"),
        table(("step", "residual RMS (µm)"), [(label, f"{v:.4g}") for label, v in steps]),
        *figures(analysis),
        "<h2>Model parameters</h2>",
        _parameter_table(model, analysis.diagnosis.base),
    ]


def write_report(analyses, out_path):
    """Write the page of one :class:`~feedaxis.analysis.Analysis` or a list of them (one
    per kind of measurement of a case) to ``out_path``; returns the path. Only formats."""
    analyses = analyses if isinstance(analyses, (list, tuple)) else [analyses]
    case = analyses[0].case
    sections = [f"<h1>feedaxis report: {html.escape(case.name)}</h1>",
                f"<p>{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, feedaxis {__version__}; "
                f"case <code>{html.escape(str(case.folder))}</code></p>"]
    for analysis in analyses:
        sections += _sections(analysis)
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>feedaxis report: "
            f"{html.escape(case.name)}</title><style>{STYLE}</style></head><body>"
            + "\n".join(sections) + "</body></html>")
    write_atomically(out_path, page)
    return Path(out_path)
