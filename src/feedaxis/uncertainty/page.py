"""The uncertainty result as one self-contained HTML page: the figures with their intervals
and histograms, each input's share, the budget with its sources, the parameters and the
compensation table with its band. Only formats: every number comes from the result."""
from __future__ import annotations

import html
from datetime import datetime, timezone

from .. import __version__
from ..output import write_atomically
from ..report import plots
from ..report.page import STYLE, image, table
from ..text import micro
from .budget import CONTRIBUTIONS
from .text import number


def _interval(pair):
    return f"[{pair[0]:.4g}, {pair[1]:.4g}]"


def _share(value):
    return "" if value is None or value != value else f"{100 * value:.1f} %"


def _figure_rows(result):
    return [(f["name"], f"{f['value_um']:.4g}", number(f["mean_um"], ".4g"),
             number(f["standard_uncertainty_um"], ".2g"), _interval(f["coverage_interval_um"]),
             _interval(f["shortest_coverage_interval_um"]))
            for f in result.figures.values()]


def _budget_rows(result):
    budget = result.budget.to_json()["contributions"]
    return [(name, "varies" if name in result.inputs else "not applied",
             entry["distribution"], f"{entry['size']:g} {micro(entry['unit'])}",
             f"{entry['standard_uncertainty']:.3g} {micro(entry['unit'])}",
             CONTRIBUTIONS[name].meaning, entry["source"])
            for name, entry in budget.items()]


def _parameter_parts(result):
    if not result.parameters:
        return []
    method = result.parameter_method
    rows = [(key, f"{e['value']:.6g}", number(e["standard_uncertainty"], ".2g"),
             f"{e['fit_standard_uncertainty']:.2g}", _interval(e["coverage_interval"]),
             micro(e["unit"])) for key, e in result.parameters.items()]
    return ["<h2>Fitted parameters</h2>",
            f"<p>{html.escape(method['method'])}; refitting {method['checked_trials']} trials "
            f"differs from it by at most {method['largest_refit_difference_in_u']:.1g} standard "
            "uncertainties. 'u fit' is the fit's own (the residual's noise alone).</p>",
            table(("parameter", "value", "u", "u fit", "95 % interval", "unit"), rows)]


def _table_parts(result):
    if not result.table:
        return []
    entry = result.table
    sides = [(label, entry[side]["value_um"],
              [pair[0] for pair in entry[side]["coverage_interval_um"]],
              [pair[1] for pair in entry[side]["coverage_interval_um"]])
             for side, label in (("forward", "+"), ("reverse", "-"))]
    return ["<h2>Compensation table</h2>",
            f"<p>From the {entry['source']} ({html.escape(', '.join(entry['included']))}), "
            f"{len(entry['position_mm'])} points, intervals over {entry['trials']} trials; "
            f"largest standard uncertainty "
            f"{number(entry['largest_standard_uncertainty_um'], '.2g')} µm.</p>",
            image(plots.table_with_uncertainty(entry["position_mm"], sides),
                  "compensation table with its coverage interval")]


def write_page(result, out_path):
    """Write the page of an :class:`~.evaluation.Uncertainty` to ``out_path``."""
    inputs = list(result.inputs)
    panels = [(f["name"], result.samples[key], f["value_um"], f["coverage_interval_um"])
              for key, f in result.figures.items()]
    correction = (f"corrected to 20 °C at {html.escape(result.correction.source)}, α = "
                  f"{result.correction.expansion_per_K:g}/K" if result.correction
                  else "not corrected to 20 °C")
    sections = [
        f"<h1>feedaxis uncertainty: {html.escape(result.case)}</h1>",
        f"<p>{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, feedaxis {__version__}. Monte "
        f"Carlo method of JCGM 101:2008, {result.trials} trials, seed {result.seed}; budget "
        f"in the structure of ISO 230-2:2014 Annex A; {correction}; repeatability from "
        f"{html.escape(result.repeatability)}.</p>",
        f"<h2>{'Every standard' if result.standard == 'all' else result.standard}'s "
        "figures</h2>",
        table(("figure", "value (µm)", "Monte Carlo mean (µm)", "u (µm)",
               "95 % interval (µm)", "shortest 95 % (µm)"), _figure_rows(result)),
        image(plots.uncertainty_histograms(panels), "histograms of the figures"),
        "<h2>Share of each input (JCGM 101 Annex B)</h2>",
        table(("figure", *inputs), [(f["name"], *(_share(f["contributions"][i]["share"])
                                                 for i in inputs))
                                    for f in result.figures.values()]),
        "<h2>Budget</h2>",
        table(("contribution", "in this run", "distribution", "size", "u", "meaning",
               "source"), _budget_rows(result)),
        *_parameter_parts(result), *_table_parts(result),
        *([f"<p>Note: {html.escape(note)}</p>" for note in result.notes]),
    ]
    title = html.escape(f"feedaxis uncertainty: {result.case}")
    write_atomically(out_path, f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>"
                               f"{title}</title><style>{STYLE}</style></head><body>"
                               + "\n".join(sections) + "</body></html>")
    return out_path
