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

from ..iso230 import FIGURE_NAMES, iso230_figures, target_groups
from ..stats.distributions import f_sf
from ..stats.wording import p_text
from .table import position_error_um

ALPHA = 0.05
LITTLE_GAIN = 0.2
DENSE_POINTS = 8001


def systematic_test(positioning):
    """One-way ANOVA of the deviations over (target, direction) groups, by group sums
    (``bincount``: linear in the samples, the p-value of scipy's ``f_oneway``).

    Returns {"p_value", "systematic_share"}: the p-value of "all group means are equal"
    (None with one sample per group) and the share of the variance between the groups.
    """
    groups = target_groups(positioning)
    error_um = positioning.error_um
    counts = np.bincount(groups)
    means = np.bincount(groups, error_um) / counts
    between_ss = float(counts @ (means - error_um.mean()) ** 2)
    within_ss = float(np.sum((error_um - means[groups]) ** 2))
    total_ss = between_ss + within_ss
    share = between_ss / total_ss if total_ss > 0 else 0.0
    between_dof, within_dof = counts.size - 1, error_um.size - counts.size
    if between_dof < 1 or within_dof < 1:
        return {"p_value": None, "systematic_share": share}
    with np.errstate(divide="ignore", invalid="ignore"):
        statistic = (between_ss / between_dof) / (within_ss / within_dof)
    p_value = float(f_sf(statistic, between_dof, within_dof))
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
        warnings.append(_little_gain(figures[key], systematic["systematic_share"]))
    return warnings


def _little_gain(figure, share):
    """Why the headline figure falls by less than ``LITTLE_GAIN`` (or rises)."""
    before, after = figure["before_um"], figure["after_um"]
    change = (f"rises from {before:.3g} to {after:.3g} µm" if after > before else
              f"only falls from {before:.3g} to {after:.3g} µm")
    if share < 1 - LITTLE_GAIN:
        return (f"{figure['name']} {change}: only {100 * share:.0f} % of the variance is "
                "systematic (the part a table removes); the rest is repeatability or drift")
    return (f"{figure['name']} {change}, although {100 * share:.0f} % of the variance is "
            "systematic (the part a table removes): the table misses it at the targets (the "
            "model lacks an effect, or the table points cannot follow it)")


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
