"""What a table is expected to do before it is loaded: the ISO 230-2 figures of the measured
case before and after the table as the controller applies it, and whether it can help.

After = measured deviation − the deviation the table removes at each target in its approach
direction (linear interpolation between the table's points, per direction). Whether a table
can help at all is a one-way analysis of variance over the (target, direction) groups: the
table can only remove what differs between groups; when their means do not differ beyond the
scatter within them (F-test, false-alarm rate ``ALPHA`` for Gaussian scatter) the error is
repeatability or drift, which no table removes.
"""
from __future__ import annotations

import numpy as np
from scipy import stats

from ..iso230 import FIGURE_NAMES, iso230_figures, target_groups
from ..stats.wording import p_text
from .table import position_error_um

ALPHA = 0.05
LITTLE_GAIN = 0.2
DENSE_POINTS = 8001


def systematic_test(positioning):
    """One-way ANOVA of the deviations over (target, direction) groups.

    Returns {"p_value", "systematic_share"}: the p-value of "all group means are equal"
    (None with one sample per group) and the share of the variance between the groups.
    """
    groups = target_groups(positioning)
    samples = [positioning.error_um[groups == g] for g in np.unique(groups)]
    total = float(np.var(positioning.error_um))
    between = float(np.var(np.array([s.mean() for s in samples])[groups]))
    share = between / total if total > 0 else 0.0
    if all(s.size < 2 for s in samples) or len(samples) < 2:
        return {"p_value": None, "systematic_share": share}
    p_value = float(stats.f_oneway(*samples).pvalue)
    return {"p_value": p_value if np.isfinite(p_value) else None, "systematic_share": share}


def verify(case, applied):
    """ISO 230-2 figures before and after the table ``applied`` (a CompTable as the
    controller reads it) on ``case``, and the warnings.

    Returns {"figures": {key: {"name", "before_um", "after_um"}}, "systematic": ...,
    "warnings": [...]}.
    """
    positioning = case.positioning
    after_um = positioning.error_um - applied.error_um(positioning.target_mm,
                                                       positioning.direction)
    before = iso230_figures(positioning.target_mm, positioning.error_um, positioning.direction)
    after = iso230_figures(positioning.target_mm, after_um, positioning.direction)
    figures = {key: {"name": name, "before_um": before[key], "after_um": after[key]}
               for key, name in FIGURE_NAMES.items() if key in before}
    systematic = systematic_test(positioning)
    return {"figures": figures, "systematic": systematic,
            "warnings": _warnings(figures, systematic)}


def _headline(figures):
    """The accuracy figure to judge by: A if both directions and runs, else E, E↑."""
    for key in ("A_um", "A_up_um", "E_um", "E_up_um", "E_down_um"):
        if key in figures:
            return key
    return None


def _warnings(figures, systematic):
    warnings = []
    p_value = systematic["p_value"]
    if p_value is not None and p_value > ALPHA:
        warnings.append(f"the table cannot help: the target means do not differ beyond the "
                        f"scatter (ANOVA {p_text(p_value)} > {ALPHA}); the error is "
                        "repeatability or drift")
    key = _headline(figures)
    if key and figures[key]["after_um"] > (1 - LITTLE_GAIN) * figures[key]["before_um"]:
        warnings.append(f"{figures[key]['name']} only falls from {figures[key]['before_um']:.3g}"
                        f" to {figures[key]['after_um']:.3g} µm: only "
                        f"{100 * systematic['systematic_share']:.0f} % of the variance is "
                        "systematic (the part a table removes); the rest is repeatability or "
                        "drift")
    return warnings


def between_targets(case, model, applied):
    """The fitted model's view between the targets: peak to valley (µm, both directions) of
    its position-table effects over ``DENSE_POINTS`` positions from the first to the last
    target, before and after the table ``applied``; None when the model has none.

    At the targets the figures of :func:`verify` are in-sample for a table made from the
    measured means there; between them only a model can say what is left.
    """
    target_mm = case.positioning.target_mm
    dense_mm = np.linspace(target_mm.min(), target_mm.max(), DENSE_POINTS)
    before, after = [], []
    for direction in (1.0, -1.0):
        predicted_um = position_error_um(case, model, dense_mm, direction)
        before.append(predicted_um)
        after.append(predicted_um - applied.error_um(dense_mm, direction))
    if not np.any(np.concatenate(before)):
        return None
    return {"pv_before_um": float(np.ptp(before)), "pv_after_um": float(np.ptp(after))}
