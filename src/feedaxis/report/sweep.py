"""The report page of a sweep: the figures' spread, what drives them, the prediction band."""
from __future__ import annotations

import html
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from .. import __version__
from ..output import write_atomically
from ..stats.wording import p_text
from ..text import micro
from .page import STYLE, image, table as html_table

MAX_SCATTERS = 4  # inputs shown against each figure, the most influential first
# fewer finished trials than this have no spread to draw: the page has no figure then (a
# histogram of one value, a band of one curve), and matplotlib is not imported (0.4 s)
MIN_SPREAD_TRIALS = 2


def histograms(figures):
    """One histogram per figure ({name: values}), the 2.5 / 50 / 97.5 % quantiles marked."""
    from .plots import _png, plt  # matplotlib, imported where a figure is drawn

    count = len(figures)
    columns = min(3, count)
    rows = -(-count // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(3.3 * columns, 2.6 * rows),
                                squeeze=False)
    for ax, (name, values) in zip(axes.ravel(), figures.items()):
        values = values[np.isfinite(values)]
        ax.hist(values, bins=min(40, max(5, values.size // 5)), color="tab:blue", alpha=0.7)
        for q in np.quantile(values, (0.025, 0.5, 0.975)) if values.size else ():
            ax.axvline(q, color="tab:red", lw=0.8, ls="--")
        ax.set_xlabel(micro(name), fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[count:]:
        ax.set_visible(False)
    axes[0, 0].set_ylabel("trials")
    return _png(figure)


def scatters(figure_name, y, inputs):
    """``y`` against each input ({name: values})."""
    from .plots import _png, plt

    figure, axes = plt.subplots(1, len(inputs), figsize=(3.3 * len(inputs), 2.8), squeeze=False)
    for ax, (name, x) in zip(axes[0], inputs.items()):
        ax.plot(x, y, ".", ms=3, alpha=0.6)
        ax.set_xlabel(micro(name), fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel(micro(figure_name), fontsize=8)
    return _png(figure)


def band_plot(band):
    """The 95 % prediction band and the median of the curve, one per group."""
    from .plots import _png, plt

    figure, axes = plt.subplots(figsize=(9, 3.6))
    x = np.asarray(band["x"])
    group = np.asarray(band["group"])
    low, mid, high = (np.asarray(band[k]) for k in ("q0.025", "q0.5", "q0.975"))
    for label in dict.fromkeys(group):
        chosen = np.flatnonzero(group == label)
        chosen = chosen[np.argsort(x[chosen], kind="stable")]
        line, = axes.plot(x[chosen], mid[chosen], "-", lw=1.0,
                          label=f"{label}: median" if len(set(group)) > 1 else "median")
        axes.fill_between(x[chosen], low[chosen], high[chosen], color=line.get_color(),
                          alpha=0.25, label="2.5-97.5 %" if label == group[0] else None)
    axes.set(xlabel=band["x_name"], ylabel=micro(band["y_name"]),
             title=f"Prediction band over {band['trials']} trials")
    axes.legend(loc="best", fontsize=7)
    axes.grid(alpha=0.3)
    return _png(figure)


def _figure_rows(summary):
    rows = []
    for name, d in summary["figures"].items():
        if d["n"]:
            q = d["quantiles"]
            rows.append((micro(name), d["n"], f"{d['mean']:.5g}",
                         "" if d["sd"] is None else f"{d['sd']:.3g}", f"{q['0.025']:.5g}",
                         f"{q['0.5']:.5g}", f"{q['0.975']:.5g}", f"{d['min']:.5g}",
                         f"{d['max']:.5g}"))
    return rows


def _sensitivity_rows(summary):
    rows = []
    for name, s in summary["sensitivities"].items():
        for input_name, v in (s.get("inputs") or {}).items():
            rows.append((micro(name), input_name, f"{v['src']:+.3f}", f"{s['r2']:.3f}",
                         f"{v['spearman']:+.3f}", p_text(v["p_value"])))
    return rows


def write_sweep_report(summary, table, out_path):
    """Write the page of a sweep (its :func:`~feedaxis.cosim.sweep.summary.summarise` and
    trial table) to ``out_path``; returns the path."""
    error = table.column("error").to_pylist()
    ok = np.array([e is None for e in error], dtype=bool)
    figures = {name: table.column(name).to_numpy(zero_copy_only=False).astype(float)[ok]
               for name in summary["figures"]}
    title = f"feedaxis sweep: {summary['scenario']}"
    sections = [
        f"<h1>{html.escape(title)}</h1>",
        f"<p>{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, feedaxis {__version__}</p>",
        f"<p>{summary['finished_trials']} of {summary['planned_trials']} trials"
        f"{'' if summary['complete'] else ' (interrupted)'}, {summary['failed_trials']} "
        f"refused by the FMUs; seed {summary['seed']}</p>",
        "<ul>" + "".join(f"<li><code>--vary {html.escape(v)}</code></li>"
                         for v in summary["vary"]) + "</ul>",
    ]
    if summary["from_model"]:
        sections.append(f"<p>parameters of <code>{html.escape(summary['from_model'])}</code> "
                        "drawn from its fit's covariance</p>")
    if summary["held"]:
        sections.append(html_table(("held at the fitted value", "why undetermined"),
                               summary["held"].items()))
    spread = ok.sum() >= MIN_SPREAD_TRIALS
    if summary["figures"] and any(d["n"] for d in summary["figures"].values()):
        sections += ["<h2>Figures</h2>",
                     html_table(("figure", "trials", "mean", "sd", "2.5 %", "50 %", "97.5 %", "min",
                             "max"), _figure_rows(summary))]
        if spread:
            sections.append(image(histograms({n: v for n, v in figures.items() if v.size}),
                                  "histograms of the figures"))
    if summary["bands"] and spread:
        sections += ["<h2>Prediction band</h2>", image(band_plot(summary["bands"]),
                                                        "prediction band")]
    if not spread:
        finished = int(ok.sum())
        sections.append(f"<p>{finished} finished trial{'' if finished == 1 else 's'}: no "
                        "spread to draw (the figures are in the table; <code>feedaxis "
                        "simulate</code> writes one run's curves)</p>")
    rows = _sensitivity_rows(summary)
    if rows:
        sections += ["<h2>Sensitivities</h2>",
                     html_table(("figure", "input", "SRC", "linear R²", "Spearman", "p"), rows)]
        for name, s in summary["sensitivities"].items():
            if s:
                ranked = sorted(s["inputs"], key=lambda n: -abs(s["inputs"][n]["src"]))
                shown = {n: table.column(n).to_numpy(zero_copy_only=False)[ok]
                         for n in ranked[:MAX_SCATTERS]}
                sections.append(image(scatters(name, figures[name], shown),
                                       f"{name} against the inputs"))
    if summary["failures"]:
        sections += ["<h2>Trials the FMUs refused</h2>",
                     html_table(("trial", "why"), [(f["trial"], f["error"])
                                               for f in summary["failures"]])]
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}"
            f"</title><style>{STYLE}</style></head><body>" + "\n".join(sections)
            + "</body></html>")
    write_atomically(out_path, page)
    return Path(out_path)
