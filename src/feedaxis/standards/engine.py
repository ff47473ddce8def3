"""One evaluation engine for every positioning standard.

The per-target statistics of a test (each target's mean deviation, sample standard
deviation and run count per approach direction: :func:`feedaxis.iso230.direction_sides`)
are computed once; a standard (:mod:`.definitions`) is a small set of formulas over them,
its figures' citations and what it asks of the test. :func:`evaluate` gives the figures;
:func:`needs` says, per figure, what the standard asks that the data lack. Both take one
set of deviations or many Monte Carlo trials' (a leading trials axis) alike.
"""
from __future__ import annotations

import math

import numpy as np

from ..iso230 import direction_sides


def statistics(target_mm, error_um, direction):
    """(targets, per-direction statistics) of :func:`feedaxis.iso230.direction_sides`:
    the number of targets and {"up"/"down": (targets_mm, mean_um, std_um, counts)}."""
    clusters, sides = direction_sides(target_mm, error_um, direction)
    return clusters[0].size, sides


def evaluate(standard, target_mm, error_um, direction):
    """{figure key: value (µm)} of ``standard`` on the deviations, in the standard's order;
    a figure the data cannot give (one direction, one run) is absent (see :func:`needs`)."""
    found = standard.formulas(*statistics(target_mm, error_um, direction))
    return {figure.key: found[figure.key] for figure in standard.figures
            if figure.key in found}


def needs(standard, target_mm, direction):
    """{figure key: [what ``standard`` asks that the data lack]}: figures it cannot give
    (no second direction, no repeated runs) and figures given from a test smaller or
    laid out otherwise than the standard's (its runs, directions, target count, spacing)."""
    targets_mm = np.unique(np.round(np.asarray(target_mm, float), 4))
    direction = np.asarray(direction, float)
    runs = {label: _runs(target_mm, direction, sign)
            for label, sign in (("up", 1.0), ("down", -1.0)) if np.any(direction == sign)}
    one_way = (f"both approach directions; the data have {'+' if 'up' in runs else '-'} "
               "only") if len(runs) < 2 else None
    common = _test_needs(standard, targets_mm, runs)
    found = {}
    for figure in standard.figures:
        missing = list(common)
        if one_way and (figure.bidirectional or standard.bidirectional):
            missing.insert(0, one_way if figure.bidirectional
                           else f"{one_way.split(';')[0]} ({standard.runs_clause})")
        if figure.side and figure.side not in runs:
            missing.insert(0, f"the {'+' if figure.side == 'up' else '-'} direction; the "
                              "data lack it")
        if figure.repeats and min(runs.values(), default=0) < 2:
            missing.insert(0, "repeated runs (a standard deviation); the data have one")
        if missing:
            found[figure.key] = missing
    return found


def _runs(target_mm, direction, sign):
    """The fewest runs at any target in the direction ``sign``."""
    chosen = np.round(np.asarray(target_mm, float)[direction == sign], 4)
    return int(np.min(np.unique(chosen, return_counts=True)[1]))


def _test_needs(standard, targets_mm, runs):
    """What the test as a whole lacks for ``standard``: runs, targets, their spacing."""
    missing = []
    fewest = min(runs.values())
    if fewest < standard.runs:
        missing.append(f"{standard.runs} runs in each direction ({standard.runs_clause}); "
                       f"the data have {fewest}")
    travel_m = float(np.ptp(targets_mm)) / 1000
    if standard.targets_per_m and travel_m <= standard.rule_travel_m:
        wanted = max(standard.min_targets, math.ceil(standard.targets_per_m * travel_m))
        if targets_mm.size < wanted:
            missing.append(f"at least {wanted} targets over {travel_m * 1000:g} mm "
                           f"({standard.targets_clause}); the data have {targets_mm.size}")
    if standard.uneven_spacing and targets_mm.size > 2 and _evenly_spaced(targets_mm):
        missing.append(f"unevenly spaced targets, so that periodic errors do not alias "
                       f"({standard.targets_clause}); the data's are evenly spaced")
    return missing


def _evenly_spaced(targets_mm):
    """True when every spacing equals the first to 1 µm."""
    spacing = np.diff(targets_mm)
    return bool(np.all(np.abs(spacing - spacing[0]) < 1e-3))
