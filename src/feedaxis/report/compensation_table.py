"""The report's "Compensation table" section: the table the fitted model gives (no
controller's point limit), plotted over the measured means, and the ISO 230-2 figures
expected after it."""
from __future__ import annotations

import html

from ..comptable import NEVER_IN_TABLE, default_spacing_mm, from_model, grid_mm, verify
from ..comptable.table import measured_means
from . import plots


def compensation_table_html(case, model, image, table):
    """HTML parts of the section (empty when the model has no effect a table can remove).

    ``image`` and ``table`` are the page's helpers for a PNG and an HTML table.
    """
    positioning = case.positioning
    target_mm = positioning.target_mm
    spacing_mm = default_spacing_mm(case, None)
    comp = from_model(case, model, grid_mm(target_mm.min(), target_mm.max(), spacing_mm))
    if not comp.included:
        return []
    check = verify(case, comp)
    (forward_mm, forward_um), (reverse_mm, reverse_um) = measured_means(positioning)
    excluded = {**comp.excluded, **{k: v for k, v in NEVER_IN_TABLE.items() if k in model}}
    parts = [
        "<h2>Compensation table</h2>",
        f"<p>From the model every {spacing_mm:.4g} mm ({comp.size} points): "
        f"{html.escape(', '.join(comp.included))}"
        + ("; direction-dependent (backlash)" if comp.bidirectional else "") + ". "
        + "".join(f"Left out {html.escape(name)}: {html.escape(reason)}. "
                  for name, reason in excluded.items())
        + "Write it for a controller with <code>feedaxis comp-table</code>.</p>",
        image(plots.compensation_table({"+": forward_mm, "-": reverse_mm},
                                       {"+": forward_um, "-": reverse_um}, comp.position_mm,
                                       {"+": comp.forward_um, "-": comp.reverse_um}),
              "compensation table over the measured means"),
        table(("ISO 230-2 figure, expected", "before (µm)", "after (µm)"),
              [(f["name"], f"{f['before_um']:.4g}", f"{f['after_um']:.4g}")
               for f in check["figures"].values()]),
    ]
    parts += [f"<p>warning: {html.escape(w)}</p>" for w in check["warnings"]]
    return parts
