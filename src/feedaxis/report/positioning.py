"""The positioning views of the report: measurement against the model between the targets,
the residual and its spatial spectrum, the ISO 230-2 deviation and figures, the thermal
compensation and the compensation table."""
from __future__ import annotations

import html

import numpy as np

from . import plots
from .compensation_table import compensation_table_html
from ..standards.text import RMS_LABEL
from .page import image, sample_contributions, table


def _positioning_views(analysis):
    """Measurement against model, the residual and its spectrum, the thermal compensation
    and the compensation table."""
    case, result, details = analysis.case, analysis.result, analysis.details
    positioning, dense = case.positioning, details.dense
    panels = _residual_panels(positioning, result.residual_um)
    parts = [
        "<h2>Measurement against model</h2>",
        image(plots.measurement_vs_model(positioning.target_mm, result.measured_um,
                                         positioning.direction,
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
                                          details.marks, analysis.diagnosis.unexplained,
                                          positioning.target_mm),
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
        return sample_contributions(analysis)
    return plots.contributions(dense.position_mm, dense.components, "position (mm)",
                               dense.line, dense.direction, dense.windows)


COLUMNS = {"measured_um": "measured (µm)", "residual_um": "residual (µm)",
           "explained": "explained", "predicted_um": "model (µm)",
           "compensated_um": "compensated (µm)"}


def _positioning_figures(analysis):
    comparison, details = analysis.comparison, analysis.details
    blocks = (comparison["standards"] if comparison["standard"] == "all"
              else {comparison["standard"]: comparison})
    html_parts = ["<h2>ISO 230-2 figures</h2>",
                  image(plots.iso230_deviation(details.iso_deviation, details.iso_line),
                        "ISO 230-2 deviation")]
    for block in blocks.values():
        html_parts += _standard_html(block, comparison)
    if any("clause" in block and block["figures"] for block in blocks.values()):
        html_parts.append(_thermal_plot(analysis.case))
    return html_parts


def _standard_html(block, comparison):
    """One standard's figures as a table, what the data lack, what is not confirmed."""
    title = html.escape(block["standard"])
    if block.get("unavailable"):
        return [f"<h3>{title}</h3>", f"<p>No figures: {html.escape(block['unavailable'])}</p>"]
    figures = list(block["figures"].values())
    columns = [key for key in COLUMNS if figures and key in figures[0]]
    rows = [(f["name"], *(_number(f[key], key) for key in columns)) for f in figures]
    if "residual_um" in columns:
        rows.append((RMS_LABEL, f"{comparison['rms_measured_um']:.4g}",
                     f"{comparison['rms_residual_um']:.4g}", ""))
    lacking = sorted({item for items in block.get("needs", {}).values() for item in items})
    return [f"<h3>{title}</h3>",
            table((f"{block['standard']} figure", *(COLUMNS[key] for key in columns)), rows),
            *(f"<p>Needs: {html.escape(item)}</p>" for item in lacking),
            f"<p>Not confirmed publicly: {html.escape(block['not_confirmed_publicly'])}</p>"]


def _number(value, key):
    if key == "explained":
        return "" if value is None else f"{100 * value:.1f} %"
    return "" if value is None else f"{value:.4g}"


def _thermal_plot(case):
    from ..compensate import thermal_error_um

    positioning = case.positioning
    return image(plots.thermal_drift(positioning.time_s, positioning.target_mm,
                                     positioning.direction, thermal_error_um(positioning),
                                     case.duty.segments),
                 "ISO 230-3 deviations over time with the duty")


def _residual_panels(positioning, residual_um):
    panels = []
    if positioning.time_s is not None:
        panels.append(("time (min)", positioning.time_s / 60.0, residual_um))
    if positioning.bidirectional:
        panels.append(("approach direction", positioning.direction, residual_um))
    if positioning.ambient_C is not None and np.ptp(positioning.ambient_C) > 0:
        panels.append(("ambient (°C)", positioning.ambient_C, residual_um))
    return panels


def _compensation_html(result):
    """Fig. 13 of Rong et al. 2023 and the before/after figures, for a thermal model on a
    thermal case."""
    if result is None:
        return []
    summary = result.summary()
    return [
        "<h2>Thermal compensation (Rong et al. 2023 Fig. 13)</h2>",
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


# the page's views, figures and contributions plot of a positioning analysis
VIEWS = (_positioning_views, _positioning_figures, _positioning_contributions)
