"""ISO 230-2 positioning figures of bidirectional (or unidirectional) runs.

x_ij = deviation at target i, run j; ↑ / ↓ = approach in + / -. With means x̄_i↑, x̄_i↓,
sample standard deviations s_i↑, s_i↓ (n - 1) and x̄_i = (x̄_i↑ + x̄_i↓)/2:
B_i = x̄_i↑ - x̄_i↓, B = max|B_i|, B̄ = mean B_i; R_i↑ = 4 s_i↑;
R_i = max(2 s_i↑ + 2 s_i↓ + |B_i|, R_i↑, R_i↓); E↑ = max x̄_i↑ - min x̄_i↑;
E = max(x̄↑, x̄↓) - min(x̄↑, x̄↓); M = max x̄_i - min x̄_i;
A = max(x̄↑ + 2s↑, x̄↓ + 2s↓) - min(x̄↑ - 2s↑, x̄↓ - 2s↓). All in µm.

The figures of one set of deviations and of many Monte Carlo trials at once (a leading
trials axis, feedaxis.uncertainty) come from the same functions.
"""
from __future__ import annotations

import weakref

import numpy as np

SAME_TARGET_MM = 1e-4  # targets closer than 0.1 µm are one target (recorded jitter)
COVERAGE = 2  # standard deviations either side of a mean: ±2s (1997, 2006, 2014 editions)


def target_clusters(target_mm, tolerance_mm=SAME_TARGET_MM):
    """(target positions in mm, target index of each sample): recorded targets closer than
    ``tolerance_mm`` to their neighbour are one target (0.1 µm: above the jitter of a
    recorded target, below any target spacing), at the mean of its samples.

    Those of a read-only array (a column as the case reader gives it) are kept, read-only
    too, while the array lives: the figures, the diagnosis and the report ask for the
    clusters of the same targets a dozen times, each a sort (1.9 s at 10^7 samples)."""
    if isinstance(target_mm, np.ndarray) and not target_mm.flags.writeable:
        kept = _KEPT_CLUSTERS.get(id(target_mm))
        if kept is not None and kept[0]() is target_mm and kept[1] == tolerance_mm:
            return kept[2]
        clusters = _clusters(target_mm, tolerance_mm)
        for part in clusters:
            part.flags.writeable = False
        key = id(target_mm)
        _KEPT_CLUSTERS[key] = (weakref.ref(target_mm, lambda _: _KEPT_CLUSTERS.pop(key, None)),
                               tolerance_mm, clusters)
        return clusters
    return _clusters(target_mm, tolerance_mm)


# {id of a read-only target array: (a weak reference to it, the tolerance, its clusters)}
_KEPT_CLUSTERS = {}


def _clusters(target_mm, tolerance_mm):
    """:func:`target_clusters`, computed."""
    target_mm = np.asarray(target_mm, dtype=float)
    order = np.argsort(target_mm, kind="stable")
    starts = np.concatenate(([True], np.diff(target_mm[order]) > tolerance_mm))
    index = np.empty(target_mm.size, dtype=index_type(target_mm.size))
    index[order] = np.cumsum(starts) - 1
    return np.bincount(index, target_mm) / np.bincount(index), index


def index_type(size):
    """The integer type of whole numbers from 0 to ``size`` (an index into ``size``
    samples): 32 bits where they fit (half the memory of a sample-sized index of 64, 40 MB
    at 10^7 samples)."""
    return np.int32 if size <= np.iinfo(np.int32).max else np.intp


def compact_index(index):
    """``index`` (integers from 0 to its size) in :func:`index_type`: the same values."""
    return index.astype(index_type(index.size), copy=False)


KEY_LIMIT = 1 << 62  # the largest mixed-radix row key row_groups builds before compacting
FEW_VALUES = 1 << 16  # a column of at most this many distinct values is ranked by search


def row_groups(*columns):
    """Index (0-based) of each sample's distinct row of ``columns`` (1-D arrays of one
    length), rows numbered in lexicographic order: ``np.unique(np.column_stack(columns),
    axis=0, return_inverse=True)[1]``, through :func:`row_key` (the structured sort of
    rows costs ten times a sort of integers at 10^6 samples)."""
    return ranks(row_key(*columns))[1]


def distinct_rows(*columns):
    """The number of distinct rows of ``columns``: of :func:`row_groups`, without them; the
    keys present counted (:func:`present_keys`), else the keys sorted in place and their
    changes counted (NumPy's unique of 10^7 distinct keys, by hashing, took 14 s)."""
    key = row_key(*columns)
    present = present_keys(key)
    if present is not None:
        return int(np.count_nonzero(present))
    key.sort()
    return int(np.count_nonzero(key[1:] != key[:-1])) + min(key.size, 1)


def present_keys(column):
    """Which of the whole numbers 0 .. max(``column``) occur in it, where ``column`` holds
    integers from 0 to fewer than its size (a dense key: a mask no larger than the column
    found in one pass); else None."""
    if column.dtype.kind not in "iu" or column.size == 0:
        return None
    if column.min() < 0 or column.max() >= column.size:
        return None
    present = np.zeros(int(column.max()) + 1, dtype=bool)
    present[column] = True
    return present


def row_key(*columns):
    """One integer per sample, in the lexicographic order of its row of ``columns``: each
    column's rank among its values appended as a digit of a mixed radix, the key ranked
    before a digit would take it past ``KEY_LIMIT`` (a rank of the key at every column
    cost a sort of every sample more per column: 4 s at 10^7 samples)."""
    key, radix = np.zeros(np.asarray(columns[0]).size, dtype=np.int64), 1
    for column in columns:
        values, index = ranks(column)
        if radix * values.size > KEY_LIMIT:
            key = ranks(key)[1]
            radix = int(key.max()) + 1
        key *= values.size  # in place: one sample-sized key, not three
        key += index
        radix *= values.size
    return key


def ranks(column):
    """(distinct values, each sample's index among them): ``np.unique(column,
    return_inverse=True)``; a column of at most ``FEW_VALUES`` values (a direction, a run
    number, a target index: as its first ``FEW_VALUES`` samples suggest) sorted as it is
    and searched, not sorted by index (twice as fast at 10^7 samples); a dense key
    (:func:`present_keys`, as a row key of distinct rows) numbered through the running
    count of the keys present (a sort of 10^7 keys took 1.7 s)."""
    column = np.asarray(column)
    present = present_keys(column)
    if present is not None:
        return np.flatnonzero(present).astype(column.dtype), (np.cumsum(present) - 1)[column]
    if np.unique(column[:FEW_VALUES]).size <= FEW_VALUES // 4:
        values = np.unique(column)
        if values.size <= FEW_VALUES:
            return values, np.searchsorted(values, column)
    values, index = np.unique(column, return_inverse=True)
    return values, index.ravel()


def per_target(target_mm, error_um, direction, sign):
    """Targets, mean, sample standard deviation (NaN for one run) and run count of one
    direction; the targets are :func:`target_clusters` of both directions together, so
    the two directions share them. ``error_um`` may carry leading trial axes
    (``(..., samples)``, a Monte Carlo's trials): the mean and standard deviation then
    carry them too (``(..., targets)``)."""
    return _per_cluster(target_clusters(target_mm), error_um, direction, sign)


def _per_cluster(clusters, error_um, direction, sign):
    """:func:`per_target` from the :func:`target_clusters` of all samples: the samples of
    one direction sorted by target once, then summed per target over the last axis, for
    one set of deviations or many trials' at once."""
    centres_mm, cluster = clusters
    chosen = np.flatnonzero(direction == sign)
    order = chosen[np.argsort(cluster[chosen], kind="stable")]
    sorted_cluster = cluster[order]
    starts = np.flatnonzero(np.concatenate(([True], np.diff(sorted_cluster) != 0)))
    counts = np.diff(np.append(starts, order.size))
    values = np.asarray(error_um, dtype=float)[..., order]
    if counts.max() == 1:  # one run: each target's mean is its one reading
        return (centres_mm[sorted_cluster], values,
                np.full(values.shape, np.nan), counts)
    mean = np.add.reduceat(values, starts, axis=-1) / counts
    squares = np.add.reduceat((values - np.repeat(mean, counts, axis=-1)) ** 2, starts,
                              axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        std = np.where(counts > 1, np.sqrt(squares / (counts - 1)), np.nan)
    return centres_mm[sorted_cluster[starts]], mean, std, counts


def _figure(value):
    """A figure as a float for one set of deviations, an array over trials for many."""
    return float(value) if np.ndim(value) == 0 else value


def _unidirectional(mean, std, counts, coverage=COVERAGE):
    figures = {"E": _figure(np.ptp(mean, axis=-1))}
    if np.all(counts > 1):
        figures["R"] = _figure(np.max(2 * coverage * std, axis=-1))
        figures["A"] = _figure(np.max(mean + coverage * std, axis=-1)
                               - np.min(mean - coverage * std, axis=-1))
    return figures


def direction_sides(target_mm, error_um, direction):
    """The per-target statistics every standard's figures start from: the
    :func:`target_clusters` of all samples and, per approach direction present (``"up"``,
    ``"down"``), its targets, means, standard deviations and run counts
    (:func:`per_target`; ``error_um`` may carry leading trial axes)."""
    target_mm, error_um = np.asarray(target_mm, float), np.asarray(error_um, float)
    direction = np.asarray(direction, float)
    clusters = target_clusters(target_mm)
    return clusters, {label: _per_cluster(clusters, error_um, direction, sign)
                      for label, sign in (("up", 1.0), ("down", -1.0))
                      if np.any(direction == sign)}


def iso230_figures(target_mm, error_um, direction, coverage=COVERAGE):
    """ISO 230-2 figures (µm) keyed ``E_up_um``, ``B_um``, ``A_um``, ...; absent when the
    data cannot give them (one direction only, or one run per target).

    ``error_um`` is one set of deviations (``(samples,)``: each figure a float) or many
    trials' (``(trials, samples)``: each figure an array over the trials), computed by the
    same formulas. ``coverage`` is the number of standard deviations either side of a mean
    (2 since the 1997 edition; 3 in the 1988 edition's ±3s convention).
    """
    clusters, sides = direction_sides(target_mm, error_um, direction)
    return figures_of_sides(clusters[0].size, sides, coverage)


def figures_of_sides(targets, sides, coverage=COVERAGE):
    """:func:`iso230_figures` from :func:`direction_sides`' per-direction statistics."""
    figures = {}
    for label, side in sides.items():
        for name, value in _unidirectional(*side[1:], coverage).items():
            figures[f"{name}_{label}_um"] = value
        figures[f"runs_{label}"] = int(np.min(side[3]))
    if len(sides) == 2 and np.array_equal(sides["up"][0], sides["down"][0]):
        figures.update(_bidirectional(sides["up"][1:], sides["down"][1:], coverage))
    figures["targets"] = int(targets)
    return figures


def _bidirectional(up, down, coverage=COVERAGE):
    (mean_up, std_up, counts_up), (mean_down, std_down, counts_down) = up, down
    reversal = mean_up - mean_down
    both = np.concatenate((mean_up, mean_down), axis=-1)
    figures = {"B_um": _figure(np.max(np.abs(reversal), axis=-1)),
               "B_mean_um": _figure(np.mean(reversal, axis=-1)),
               "E_um": _figure(np.ptp(both, axis=-1)),
               "M_um": _figure(np.ptp((mean_up + mean_down) / 2, axis=-1))}
    if np.all(counts_up > 1) and np.all(counts_down > 1):
        k = coverage
        r_i = np.maximum.reduce([k * std_up + k * std_down + np.abs(reversal),
                                 2 * k * std_up, 2 * k * std_down])
        figures["R_um"] = _figure(np.max(r_i, axis=-1))
        highest = np.maximum(np.max(mean_up + k * std_up, axis=-1),
                             np.max(mean_down + k * std_down, axis=-1))
        lowest = np.minimum(np.min(mean_up - k * std_up, axis=-1),
                            np.min(mean_down - k * std_down, axis=-1))
        figures["A_um"] = _figure(highest - lowest)
    return figures


FIGURE_NAMES = {
    "A_um": "accuracy A", "E_um": "systematic deviation E", "M_um": "mean positioning error M",
    "R_um": "repeatability R", "B_um": "reversal B", "B_mean_um": "mean reversal B̄",
    "E_up_um": "systematic deviation E↑", "E_down_um": "systematic deviation E↓",
    "R_up_um": "repeatability R↑", "R_down_um": "repeatability R↓",
    "A_up_um": "accuracy A↑", "A_down_um": "accuracy A↓",
}


def sampling_notes(target_mm, direction, run=None):
    """What the figures do with the samples that a reader would not assume: samples that
    repeat another's target, direction and run (pooled with it, as one more run there),
    and targets read by fewer runs than others (each figure uses every run; R and A need
    two at every target). Returns a list of sentences (empty when the test is even)."""
    _, cluster = target_clusters(target_mm)
    direction = np.asarray(direction, float)
    notes = []
    if run is not None:
        repeated = cluster.size - (distinct_rows(cluster, direction, run) if cluster.size else 0)
        if repeated:
            notes.append(f"{repeated} sample{'s' if repeated > 1 else ''} repeat the target, "
                         "direction and run of another: pooled with it as further runs at "
                         "that target")
    for sign, label in ((1.0, "+"), (-1.0, "-")):
        counts = np.bincount(cluster[direction == sign])
        counts = counts[counts > 0]
        if counts.size and counts.min() != counts.max():
            notes.append(f"uneven runs in {label}: {counts.min()} to {counts.max()} per "
                         "target; each target's mean and s use its own runs"
                         + ("; R and A need two at every target, so they are not given"
                            if counts.min() < 2 else ""))
    return notes


def target_groups(positioning, clusters=None):
    """Group index of each sample: one group per (target, approach direction), the targets
    from :func:`target_clusters` (``clusters``, when already computed)."""
    _, cluster = clusters or target_clusters(positioning.target_mm)
    keys = cluster * 2 + (positioning.direction > 0)
    return compact_index(ranks(keys)[1])
