"""The self-contained HTML report: tables and PNG plots embedded as data URIs.

One page for every kind of measurement: the header, the diagnosis, the kind's own views
(each kind's module in this package: :mod:`.positioning`, :mod:`.tracking`), each effect's
contribution, the error ladder, the figures and the model's parameters. It only formats
:class:`~feedaxis.analysis.Analysis` objects: every number comes from them.
"""
from __future__ import annotations

import base64
import html
import re
from datetime import datetime, timezone
from pathlib import Path

from .. import __version__
from ..effects.base import BasisEffect
from ..kinds import part
from ..output import write_atomically
from ..stats.wording import p_text
from ..text import micro, repeatability_text

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


def _beside(diagnosis):
    """What the diagnosis fitted beside the model (its RMS includes it), as text."""
    beside = [e.name for e in diagnosis.base.model.effects if isinstance(e, BasisEffect)]
    return f" ({', '.join(beside)} fitted beside the model)" if beside else ""


def _diagnosis_html(analysis):
    diagnosis, measurement = analysis.diagnosis, analysis.measurement
    location = f"{measurement.location_key.rsplit('_', 1)[0]} ({measurement.location_unit})"
    parts = [f'<p class="verdict">verdict: {diagnosis.verdict}</p>',
             f"<p>residual RMS {diagnosis.rms_um:.4g} µm{_beside(diagnosis)}; noise "
             f"{diagnosis.noise_um:.3g} µm ({html.escape(diagnosis.noise_source)})</p>"]
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


def sample_contributions(analysis):
    """Each effect's contribution at the samples, against their coordinate."""
    from . import plots  # matplotlib, imported where a figure is drawn

    measurement = analysis.measurement
    return plots.contributions(measurement.coordinate, analysis.components,
                               measurement.coordinate_label)


def _no_views(analysis):
    return []


def _sections(analysis):
    """The page's sections for one analysis: the kind's views, figures and contributions
    plot (:func:`feedaxis.kinds.part` ``views``), each where the page places it."""
    from . import plots  # matplotlib, imported where a figure is drawn

    views, figures, contributions = (part(type(analysis.measurement), "views")
                                     or (_no_views, _no_views, sample_contributions))
    measurement, result, model = analysis.measurement, analysis.result, analysis.model
    steps = analysis.ladder
    return [
        f"<h2>{analysis.kind.capitalize()} ({measurement.file})</h2>",
        f"<p>{html.escape(measurement.describe())}; model: "
        f"{html.escape(' + '.join(model.names) or '(no effect: ' + measurement.reference_label + ')')}"
        f"; residual RMS of the model alone {result.rms_um:.4g} µm of "
        f"{result.statistics.rms_before_um:.4g} µm measured (R² {result.statistics.r2:.4f})</p>",
        "<h2>Diagnosis</h2>", _diagnosis_html(analysis),
        *views(analysis),
        "<h2>Each effect's contribution</h2>",
        image(contributions(analysis), "contributions") if model.effects
        else "<p>(no effect in the model)</p>",
        "<h2>Error ladder</h2>", image(plots.ladder(steps, analysis.diagnosis.noise_um),
                                       "error ladder"),
        table(("step", "residual RMS, the model alone (µm)"),
              [(label, f"{v:.4g}") for label, v in steps]),
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
