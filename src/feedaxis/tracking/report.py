"""The HTML report of a tracking case: the plots a servo engineer reads, then the numbers."""
from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from ..effects import Model
from ..output import write_atomically
from ..report.page import STYLE, _image, _parameter_table, _table
from ..report.plots import ladder
from . import plots
from .compare import compare
from .diagnose import diagnose
from .fit import evaluate, fit
from .model import components
from .tests import periodogram


def error_ladder(case, model):
    """[(label, residual RMS µm)]: seed 002's plant with the drive's controller, then each
    effect of ``model`` added in turn, refitted."""
    steps = [("seed 002 plant", evaluate(Model(), [case]).rms_um)]
    for count in range(1, len(model.effects) + 1):
        partial = Model(model.effects[:count])
        steps.append((f"+ {model.effects[count - 1].name}", fit(partial, [case]).rms_um))
    return steps


def _diagnosis_html(diagnosis):
    parts = [f'<p class="verdict">verdict: {diagnosis.verdict}</p>',
             f"<p>residual RMS {diagnosis.rms_um:.4g} µm; noise {diagnosis.noise_um:.3g} µm "
             f"({html.escape(diagnosis.noise_source)})</p>"]
    if diagnosis.candidates:
        parts.append(_table(("missing effect", "RMS after (µm)", "p", "meaning", "evidence"),
                            [(c.effect, f"{c.rms_after_um:.4g}", f"{c.p_value:.2g}", c.meaning,
                              c.evidence) for c in diagnosis.candidates]))
    if diagnosis.unexplained:
        parts.append(_table(("unexplained", "frequency (Hz)", "amplitude (µm)", "evidence"),
                            [(s.kind, "" if s.frequency_hz is None else f"{s.frequency_hz:.4g}",
                              f"{s.amplitude_um:.3g}", s.evidence) for s in diagnosis.unexplained]))
    return "\n".join(parts)


def _comparison_html(comparison):
    maximum, rms = comparison["max_tracking_error_mm"], comparison["rms_tracking_error_mm"]
    return _table(("after the first second", "measured (mm)", "predicted (mm)"),
                  [("max tracking error", f"{maximum['measured']:.5f}",
                    f"{maximum['predicted']:.5f}"),
                   ("RMS tracking error", f"{rms['measured']:.5f}", f"{rms['predicted']:.5f}")])


def write_report(case, model, effects, out_path):
    """Write the report of ``model`` (as fitted) on the tracking ``case``; returns the path."""
    tracking = case.tracking
    result = evaluate(model, [case])
    diagnosis = diagnose(case, model, effects)
    steps = error_ladder(case, model)
    velocity_mm_s = np.gradient(tracking.reference_mm, tracking.time_s)
    reversals_s = tracking.time_s[1:][np.diff(np.sign(velocity_mm_s)) != 0]
    step_s = float(np.median(np.diff(tracking.time_s)))
    frequency_hz, power = periodogram(result.residual_um, step_s)
    amplitude_um = 2.0 * np.sqrt(power / result.residual_um.size)
    sections = [
        f"<h1>feedaxis tracking report: {html.escape(case.name)}</h1>",
        f"<p>case <code>{html.escape(str(case.folder))}</code>, {tracking.time_s.size} samples "
        f"over {np.ptp(tracking.time_s):.4g} s, {case.axis.servo['controller'].upper()} "
        f"controller; model: {html.escape(' + '.join(model.names) or '(seed 002 plant)')}; "
        f"residual RMS {result.rms_um:.4g} µm</p>",
        "<h2>Diagnosis</h2>", _diagnosis_html(diagnosis),
        "<h2>Tracking error (seed 002)</h2>", _comparison_html(compare(case, model)),
        _image(plots.error_against_time(tracking.time_s, result.measured_um,
                                        result.measured_um - result.residual_um, reversals_s),
               "tracking deviation against time"),
        _image(plots.error_against_velocity(velocity_mm_s, result.measured_um, result.residual_um),
               "tracking deviation against velocity"),
        "<h2>Residual spectrum</h2>",
        _image(plots.residual_spectrum(frequency_hz, amplitude_um, diagnosis.unexplained),
               "residual spectrum"),
        "<h2>Each effect's contribution</h2>",
        _image(plots.contributions(tracking.time_s, components(case, model)), "contributions")
        if model.effects else "<p>(no effect: seed 002's plant)</p>",
        "<h2>Error ladder</h2>", _image(ladder(steps, diagnosis.noise_um), "error ladder"),
        _table(("step", "residual RMS (µm)"), [(label, f"{v:.4g}") for label, v in steps]),
        "<h2>Model parameters</h2>",
        _parameter_table(model, diagnosis.base),
    ]
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>feedaxis tracking "
            f"report: {html.escape(case.name)}</title><style>{STYLE}</style></head><body>"
            + "\n".join(sections) + "</body></html>")
    write_atomically(out_path, page)
    return Path(out_path)
