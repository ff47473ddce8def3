"""The report's "Compensation table" section: the table the fitted model gives (no
controller's point limit), plotted over the measured means, and the ISO 230-2 figures
expected after it."""
from __future__ import annotations

import html

from ..comptable import NEVER_IN_TABLE
from ..comptable.table import measured_means
from . import plots


def compensation_table_html(analysis, image, table):
    """HTML parts of the section (empty when the model has no effect a table can remove).

    ``image`` and ``table`` are the page's helpers for a PNG and an HTML table.
    """
    details = analysis.details
    comp, check, spacing_mm = details.comp_table, details.comp_check, details.comp_spacing_mm
    if comp is None:
        return []
    model, positioning = analysis.model, analysis.case.positioning
    measured = dict(zip(("+", "-"), measured_means(positioning)))
    table_um = {"+": comp.forward_um, "-": comp.reverse_um}
    directions = ("+", "-") if positioning.bidirectional else ("+",)
    excluded = {**comp.excluded, **{k: v for k, v in NEVER_IN_TABLE.items() if k in model}}
    parts = [
        "<h2>Compensation table</h2>",
        f"<p>From the model every {spacing_mm:.4g} mm ({comp.size} points): "
        f"{html.escape(', '.join(comp.included))}"
        + ("; direction-dependent (backlash)" if comp.bidirectional else "") + ". "
        + "".join(f"Left out {html.escape(name)}: {html.escape(reason)}. "
                  for name, reason in excluded.items())
        + "Write it for a controller with <code>feedaxis comp-table</code>.</p>",
        image(plots.compensation_table({d: measured[d][0] for d in directions},
                                       {d: measured[d][1] for d in directions},
                                       comp.position_mm, {d: table_um[d] for d in directions}),
              "compensation table over the measured means"),
        table(("ISO 230-2 figure, expected", "before (µm)", "after (µm)"),
              [(f["name"], f"{f['before_um']:.4g}", f"{f['after_um']:.4g}")
               for f in check["figures"].values()]),
    ]
    parts += [f"<p>warning: {html.escape(w)}</p>" for w in check["warnings"]]
    return parts
