"""The self-contained HTML report: tables and PNG plots embedded as data URIs."""
from __future__ import annotations

import html
import re
from datetime import datetime, timezone
from pathlib import Path

from .. import __version__

from ..output import write_atomically
from . import plots
from .html import document, image as _image, table as _table
from .compensation_table import compensation_table_html

def micro(unit):
    """A unit as the page writes it: µm, not um."""
    return re.sub(r"\bum\b", "µm", unit)


def _parameter_rows(model, uncertainties, undetermined):
    """(parameter, value, standard uncertainty, unit, meaning) per fitted parameter."""
    rows = []
    for e in model.effects:
        for p in e.parameters:
            sigma = uncertainties.get(e.name, {}).get(p.name)
            note = undetermined.get(f"{e.name}.{p.name}", "")
            rows.append((f"{e.name}.{p.name}", f"{model.values[e.name][p.name]:.6g}",
                         note or ("" if sigma is None else f"{sigma:.2g}"), micro(p.unit),
                         p.meaning))
    return rows


def _parameter_table(model, refit):
    """The model's parameters with the standard uncertainties of ``refit`` (its refit on
    the case: the diagnosis's base)."""
    return _table(("parameter", "value", "standard uncertainty", "unit", "meaning"),
                  _parameter_rows(model, refit.uncertainties, refit.undetermined))


def _diagnosis_html(diagnosis):
    parts = [f'<p class="verdict">verdict: {diagnosis.verdict}</p>',
             f"<p>residual RMS {diagnosis.rms_um:.4g} µm; noise {diagnosis.noise_um:.3g} µm "
             f"({html.escape(diagnosis.noise_source)})</p>"]
    if diagnosis.candidates:
        parts.append(_table(("missing effect", "RMS after (µm)", "p-value", "meaning", "evidence"),
                            [(c.effect, f"{c.rms_after_um:.4g}", f"{c.test.p_value:.2g}", c.meaning,
                              c.evidence) for c in diagnosis.candidates]))
    if diagnosis.unexplained:
        parts.append(_table(("unexplained", "wavelength (mm)", "amplitude (µm)", "evidence"),
                            [(s.kind, "" if s.wavelength_mm is None else f"{s.wavelength_mm:.4g}",
                              f"{s.amplitude_um:.3g}", s.evidence) for s in diagnosis.unexplained]))
    if diagnosis.outlier_rows:
        parts.append(f"<p>outliers kept out of the fit, rows of positioning.csv: "
                     f"{', '.join(map(str, diagnosis.outlier_rows))}</p>")
    parts.append(f"<p>{html.escape(diagnosis.test_used)}</p>")
    if diagnosis.skipped:
        parts.append(_table(("passed over", "why"), diagnosis.skipped.items()))
    return "".join(parts)


def _comparison_html(comparison):
    rows = [(f["name"], f"{f['measured_um']:.4g}", f"{f['residual_um']:.4g}",
             "" if f["explained"] is None else f"{100 * f['explained']:.1f} %")
            for f in comparison["figures"].values()]
    rows.append(("RMS", f"{comparison['rms_measured_um']:.4g}",
                 f"{comparison['rms_residual_um']:.4g}", ""))
    return _table(("ISO 230-2 figure", "measured (µm)", "residual (µm)", "explained"), rows)


def _residual_panels(case, residual_um):
    positioning = case.positioning
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
        _image(plots.thermal_compensation(result.target_mm, result.visit, result.time_s,
                                          result.thermal_error_um, result.left_um),
               "thermal error without and with compensation"),
        _table(("target (mm)", "dir", "max before (µm)", "max after (µm)", "RMS before (µm)",
                "RMS after (µm)"),
               [(f"{r['target_mm']:g}", f"{r['direction']:+d}", f"{r['max_before_um']:.3g}",
                 f"{r['max_after_um']:.3g}", f"{r['rms_before_um']:.3g}",
                 f"{r['rms_after_um']:.3g}") for r in result.by_target()]),
    ]


def write_report(analysis, out_path):
    """Write the page of an :class:`~feedaxis.analysis.Analysis` to ``out_path``; returns
    the path. Only formats: every number comes from ``analysis``."""
    case, model = analysis.case, analysis.model
    result, diagnosis, steps = analysis.result, analysis.diagnosis, analysis.ladder
    positioning = case.positioning
    sections = [
        f"<h1>feedaxis report: {html.escape(case.name)}</h1>",
        f"<p>{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, feedaxis {__version__}</p>",
        f"<p>case <code>{html.escape(str(case.folder))}</code>, {positioning.size} samples; "
        f"model: {html.escape(' + '.join(model.names) or '(empty)')}; residual RMS "
        f"{result.rms_um:.4g} µm of {result.statistics.rms_before_um:.4g} µm measured "
        f"(R² {result.statistics.r2:.4f})</p>",
        "<h2>Diagnosis</h2>", _diagnosis_html(diagnosis),
        "<h2>Measurement against model</h2>",
        _image(plots.measurement_vs_model(positioning.target_mm, result.measured_um,
                                          result.measured_um - result.residual_um,
                                          positioning.direction, analysis.run_of_sample),
               "measurement against model"),
        "<h2>Residual</h2>",
        _image(plots.residual_vs_position(positioning.target_mm, result.residual_um,
                                          diagnosis.spectrum.marks), "residual against position"),
        _image(plots.spectrum((diagnosis.spectrum.wavelength_mm, diagnosis.spectrum.amplitude_um),
                              analysis.measured_spectrum,
                              diagnosis.spectrum.marks, diagnosis.unexplained), "spectrum"),
    ]
    panels = _residual_panels(case, result.residual_um)
    if panels:
        sections.append(_image(plots.residual_against(panels), "residual against time, "
                                                               "direction, ambient"))
    sections += _compensation_html(analysis.compensation)
    sections += compensation_table_html(analysis, _image, _table)
    sections += [
        "<h2>Each effect's contribution</h2>",
        _image(plots.contributions(positioning.target_mm, analysis.components),
               "contributions") if model.effects else "<p>(empty model)</p>",
        "<h2>Error ladder</h2>", _image(plots.ladder(steps, diagnosis.noise_um), "error ladder"),
        _table(("step", "residual RMS (µm)"), [(label, f"{v:.4g}") for label, v in steps]),
        "<h2>ISO 230-2 figures</h2>",
        _image(plots.iso230_deviation(analysis.iso_deviation), "ISO 230-2 deviation"),
        _comparison_html(analysis.comparison),
        "<h2>Model parameters</h2>",
        _parameter_table(model, diagnosis.base),
    ]
    write_atomically(out_path, document(f"feedaxis report: {case.name}", sections))
    return Path(out_path)
