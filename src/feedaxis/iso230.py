"""ISO 230-2 positioning figures of bidirectional (or unidirectional) runs.

x_ij = deviation at target i, run j; ↑ / ↓ = approach in + / -. With means x̄_i↑, x̄_i↓,
sample standard deviations s_i↑, s_i↓ (n - 1) and x̄_i = (x̄_i↑ + x̄_i↓)/2:
B_i = x̄_i↑ - x̄_i↓, B = max|B_i|, B̄ = mean B_i; R_i↑ = 4 s_i↑;
R_i = max(2 s_i↑ + 2 s_i↓ + |B_i|, R_i↑, R_i↓); E↑ = max x̄_i↑ - min x̄_i↑;
E = max(x̄↑, x̄↓) - min(x̄↑, x̄↓); M = max x̄_i - min x̄_i;
A = max(x̄↑ + 2s↑, x̄↓ + 2s↓) - min(x̄↑ - 2s↑, x̄↓ - 2s↓). All in µm.
"""
from __future__ import annotations

import numpy as np

SAME_TARGET_MM = 1e-4  # targets closer than 0.1 µm are one target (recorded jitter)


def target_clusters(target_mm, tolerance_mm=SAME_TARGET_MM):
    """(target positions in mm, target index of each sample): recorded targets closer than
    ``tolerance_mm`` to their neighbour are one target (0.1 µm: above the jitter of a
    recorded target, below any target spacing), at the mean of its samples."""
    target_mm = np.asarray(target_mm, dtype=float)
    order = np.argsort(target_mm, kind="stable")
    starts = np.concatenate(([True], np.diff(target_mm[order]) > tolerance_mm))
    index = np.empty(target_mm.size, dtype=int)
    index[order] = np.cumsum(starts) - 1
    return np.bincount(index, target_mm) / np.bincount(index), index


def per_target(target_mm, error_um, direction, sign):
    """Targets, mean, sample standard deviation (NaN for one run) and run count of one
    direction; the targets are :func:`target_clusters` of both directions together, so
    the two directions share them."""
    return _per_cluster(target_clusters(target_mm), error_um, direction, sign)


def _per_cluster(clusters, error_um, direction, sign):
    """:func:`per_target` from the :func:`target_clusters` of all samples."""
    centres_mm, cluster = clusters
    chosen = direction == sign
    used, index = np.unique(cluster[chosen], return_inverse=True)
    unique_mm = centres_mm[used]
    counts = np.bincount(index)
    mean = np.bincount(index, error_um[chosen]) / counts
    squares = np.bincount(index, (error_um[chosen] - mean[index]) ** 2)
    with np.errstate(invalid="ignore", divide="ignore"):
        std = np.where(counts > 1, np.sqrt(squares / (counts - 1)), np.nan)
    return unique_mm, mean, std, counts


def _unidirectional(mean, std):
    figures = {"E": float(np.ptp(mean))}
    if not np.any(np.isnan(std)):
        figures["R"] = float(np.max(4 * std))
        figures["A"] = float(np.max(mean + 2 * std) - np.min(mean - 2 * std))
    return figures


def iso230_figures(target_mm, error_um, direction):
    """ISO 230-2 figures (µm) keyed ``E_up_um``, ``B_um``, ``A_um``, ...; absent when the
    data cannot give them (one direction only, or one run per target)."""
    target_mm, error_um = np.asarray(target_mm, float), np.asarray(error_um, float)
    direction = np.asarray(direction, float)
    clusters = target_clusters(target_mm)
    figures = {}
    sides = {}
    for label, sign in (("up", 1.0), ("down", -1.0)):
        if np.any(direction == sign):
            sides[label] = _per_cluster(clusters, error_um, direction, sign)
            for name, value in _unidirectional(*sides[label][1:3]).items():
                figures[f"{name}_{label}_um"] = value
            figures[f"runs_{label}"] = int(np.min(sides[label][3]))
    if len(sides) == 2 and np.array_equal(sides["up"][0], sides["down"][0]):
        figures.update(_bidirectional(sides["up"][1:3], sides["down"][1:3]))
    figures["targets"] = int(clusters[0].size)
    return figures


def _bidirectional(up, down):
    (mean_up, std_up), (mean_down, std_down) = up, down
    reversal = mean_up - mean_down
    both = np.concatenate((mean_up, mean_down))
    figures = {"B_um": float(np.max(np.abs(reversal))), "B_mean_um": float(np.mean(reversal)),
               "E_um": float(np.ptp(both)), "M_um": float(np.ptp((mean_up + mean_down) / 2))}
    if not (np.any(np.isnan(std_up)) or np.any(np.isnan(std_down))):
        r_i = np.maximum.reduce([2 * std_up + 2 * std_down + np.abs(reversal),
                                 4 * std_up, 4 * std_down])
        figures["R_um"] = float(np.max(r_i))
        figures["A_um"] = float(max(np.max(mean_up + 2 * std_up), np.max(mean_down + 2 * std_down))
                                - min(np.min(mean_up - 2 * std_up), np.min(mean_down - 2 * std_down)))
    return figures


FIGURE_NAMES = {
    "A_um": "accuracy A", "E_um": "systematic deviation E", "M_um": "mean positioning error M",
    "R_um": "repeatability R", "B_um": "reversal B", "B_mean_um": "mean reversal B̄",
    "E_up_um": "systematic deviation E↑", "E_down_um": "systematic deviation E↓",
    "R_up_um": "repeatability R↑", "R_down_um": "repeatability R↓",
    "A_up_um": "accuracy A↑", "A_down_um": "accuracy A↓",
}


def target_groups(positioning):
    """Group index of each sample: one group per (target, approach direction), the targets
    from :func:`target_clusters`."""
    _, cluster = target_clusters(positioning.target_mm)
    keys = cluster * 2 + (positioning.direction > 0)
    return np.unique(keys, return_inverse=True)[1].ravel()
