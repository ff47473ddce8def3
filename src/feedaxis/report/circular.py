"""The report's views of a circular test: the polar trace as ballbar users read it, the
ISO 230-4 figures and the set-up. Formats an Analysis, computes nothing."""
from __future__ import annotations

from . import page, plots


def views(analysis):
    """The polar trace: measured, model and residual (the set-up taken out of each), both
    directions, with their ISO 230-4 figures."""
    measurement, result = analysis.measurement, analysis.result
    figures = analysis.comparison["figures"]
    model_um = measurement.measured_um - result.residual_um

    def text(column):
        return ", ".join(f"{key[:-3].replace('_', ' ')} {figures[key][column]:.3g}"
                         for key in ("G_um", "H_um") if key in figures) + " µm"

    traces = {"measured": measurement.measured_um, "model": model_um,
              "residual": result.residual_um}
    return ["<h2>The circle (polar trace)</h2>",
            page.image(plots.polar_traces(measurement.angle_deg, measurement.direction, traces,
                                     {"measured": text("measured_um"),
                                      "residual": text("residual_um")}),
                  "polar trace of the circular test")]


def figures(analysis):
    comparison = analysis.comparison
    rows = [(f["name"], f["center"], f"{f['measured_um']:.4g}", f"{f['residual_um']:.4g}",
             "" if f["explained"] is None else f"{100 * f['explained']:.1f} %")
            for f in comparison["figures"].values()]
    setup = comparison["setup"]
    first, second = comparison["axes"]
    return ["<h2>ISO 230-4 figures</h2>",
            page.table(("ISO 230-4 figure", "about the centre", "measured (µm)", "residual (µm)",
                        "explained"), rows),
            "<h2>The set-up (not the machine's)</h2>",
            page.table(("set-up", "value"),
                  [(f"centre offset along {first}", f"{setup['center_first_um']:.4g} µm"),
                   (f"centre offset along {second}", f"{setup['center_second_um']:.4g} µm"),
                   ("radius", f"{setup['radius_um']:.4g} µm"),
                   ("drift of the instrument", f"{setup['drift_um_per_s']:.4g} µm/s")])]


VIEWS = (views, figures, page.sample_contributions)
