"""The Monte Carlo method of JCGM 101:2008 (GUM Supplement 1) over any measurement model.

A model is a ``sample(streams, trials, active, skip) -> {output: array (trials, ...)}``
function: ``streams`` maps each input quantity to its own random generator, ``active``
names the inputs that vary (the others stay at their estimates), ``skip`` the outputs no
longer wanted (it may leave them out). Trials run in chunks, so memory
stays bounded whatever their number. This module gives

- the estimate, standard uncertainty (§7.6) and the probabilistically symmetric and
  shortest 95 % coverage intervals (§7.7) of every output,
- the adaptive procedure of §7.9.4 (blocks of 10^4 trials until twice the standard
  deviation of each block result is within the asked numerical tolerance),
- each input's contribution (Annex B): its standard uncertainty of the output when it
  alone varies, and its share of the sum of their squares.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

COVERAGE = 0.95
DEFAULT_TRIALS = 200_000  # §7.2.1 note: M at least 10^4 / (1 - p) for p = 95 %
MIN_TRIALS = 1_000
BLOCK_TRIALS = 10_000  # §7.9.4 a): M = max(J, 10^4) trials a block, J = 100 / (1 - p)
MAX_BLOCKS = 200  # the adaptive procedure gives up (and says so) after 2·10^6 trials
CONTRIBUTION_TRIALS = 10_000
MOMENTS = ("mean", "standard_uncertainty")  # the Summary fields that are moments
# An output without a variance (the t of 2 or 3 runs) has block interval ends scattered
# by its heavy tails; their s over h blocks (h - 1 degrees of freedom) needs h >= 10 to be
# within about 25 % (measured: with 2 blocks, 5 seeds' ends spread over twice the tolerance).
MIN_BLOCKS_WITHOUT_VARIANCE = 10


def run(sample, inputs, trials, seed, chunk_trials, active=None, block=0, progress=None,
        keep=None):
    """``trials`` trials of ``sample`` in chunks of ``chunk_trials``: {output: (trials, ...)}.

    Chunk ``c`` of block ``block`` draws from generators seeded by (``seed``, block, c,
    input): the same seed gives the same values, and an input's values do not depend on
    which other inputs are active. ``keep`` ({output: trials}) keeps only the first trials
    of a large output (memory, and the time to sort it).
    """
    active = tuple(inputs) if active is None else tuple(active)
    keep = keep or {}
    parts = []
    for chunk, start in enumerate(range(0, trials, chunk_trials)):
        count = min(chunk_trials, trials - start)
        streams = {name: np.random.default_rng(np.random.SeedSequence(
            seed, spawn_key=(block, chunk, index))) for index, name in enumerate(inputs)}
        skip = frozenset(key for key, limit in keep.items() if limit <= start)
        values = sample(streams, count, active, skip)
        parts.append({key: value[:max(0, keep[key] - start)] if key in keep else value
                      for key, value in values.items()})
        if progress:
            progress(count)
    return {key: np.concatenate([part[key] for part in parts if key in part])
            for key in parts[0]}


@dataclass(frozen=True)
class Summary:
    """Per output (arrays shaped like one trial's output): the Monte Carlo estimate (the
    trials' mean), standard uncertainty, and the 95 % coverage intervals."""

    mean: np.ndarray
    standard_uncertainty: np.ndarray
    symmetric: np.ndarray  # (2, ...): low, high
    shortest: np.ndarray


def summarise(values, coverage=COVERAGE):
    """:class:`Summary` of ``values`` (trials along axis 0), JCGM 101 §7.6-7.7: q = pM
    rounded; the symmetric interval from the r-th smallest value, r = ⌊(M - q + 1)/2⌋,
    the shortest the one of the M - q intervals [y_(r), y_(r+q)] of least length."""
    values = np.asarray(values, dtype=float)
    trials = values.shape[0]
    ordered = np.sort(values, axis=0)
    q = int(coverage * trials + 0.5)
    low = (trials - q + 1) // 2 - 1
    symmetric = ordered[[low, low + q]]
    lengths = ordered[q:] - ordered[:trials - q]
    start = np.argmin(lengths, axis=0)[np.newaxis]
    shortest = np.concatenate((np.take_along_axis(ordered, start, axis=0),
                               np.take_along_axis(ordered, start + q, axis=0)))
    return Summary(values.mean(axis=0), values.std(axis=0, ddof=1), symmetric, shortest)


@dataclass(frozen=True)
class Adaptive:
    """How the adaptive procedure ended: the blocks and trials it took, the numerical
    tolerance asked and the one reached (the largest twice-standard-deviation of a block
    result, over the outputs judged), and whether it stabilised."""

    blocks: int
    trials: int
    tolerance: float
    reached: float
    stabilised: bool

    def to_json(self):
        return {"blocks": self.blocks, "trials": self.trials, "tolerance_um": self.tolerance,
                "reached_um": self.reached, "stabilised": self.stabilised}


def run_adaptive(sample, inputs, tolerance, judged, seed, chunk_trials, progress=None,
                 max_blocks=MAX_BLOCKS, keep=None, moments=MOMENTS, min_blocks=2):
    """JCGM 101 §7.9.4: blocks of :data:`BLOCK_TRIALS` trials until, for every output in
    ``judged``, twice the standard deviation of the block means, standard uncertainties and
    interval ends (each over h blocks, s = sqrt(Σ(y_r - ȳ)² / (h(h - 1)))) is at most
    ``tolerance``; only those of ``moments`` ("mean", "standard_uncertainty") that exist
    are judged (an output without a variance has block u that never settle), the interval
    ends always; at least ``min_blocks`` blocks (the s of h blocks has h - 1 degrees of
    freedom: of 2 blocks of a heavy-tailed output it says little). Returns ({output: all
    trials' values}, :class:`Adaptive`)."""
    blocks, results = [], []
    reached = np.inf
    while len(blocks) < max_blocks:
        kept = {key: max(0, limit - len(blocks) * BLOCK_TRIALS)
                for key, limit in (keep or {}).items()}
        values = run(sample, inputs, BLOCK_TRIALS, seed, chunk_trials, block=len(blocks),
                     progress=progress, keep=kept)
        blocks.append(values)
        results.append(_block_results(values, judged, moments))
        if len(blocks) >= max(2, min_blocks):
            stacked = np.array(results)
            h = len(results)
            spread = np.sqrt(np.sum((stacked - stacked.mean(axis=0)) ** 2, axis=0)
                             / (h * (h - 1)))
            reached = float(np.max(2 * spread))
            if reached <= tolerance:
                break
    merged = {key: np.concatenate([block[key] for block in blocks if key in block])
              for key in blocks[0]}
    return merged, Adaptive(len(blocks), len(blocks) * BLOCK_TRIALS, tolerance, reached,
                            reached <= tolerance)


def _block_results(values, judged, moments=MOMENTS):
    """The block results of §7.9.4 c) of every judged output, flattened: the interval
    ends, and the mean and standard uncertainty where ``moments`` says they exist."""
    parts = []
    for key in judged:
        summary = summarise(values[key])
        parts += [getattr(summary, moment).ravel() for moment in moments]
        parts += [summary.symmetric[0].ravel(), summary.symmetric[1].ravel()]
    return np.concatenate(parts)


def contributions(sample, inputs, seed, chunk_trials, trials=CONTRIBUTION_TRIALS,
                  progress=None):
    """JCGM 101 Annex B: {input: {output: standard uncertainty with that input alone
    varying}} over ``trials`` trials each (the others at their estimates)."""
    found = {}
    for name in inputs:
        values = run(sample, inputs, trials, seed, chunk_trials, active=(name,),
                     progress=progress)
        found[name] = {key: value.std(axis=0, ddof=1) for key, value in values.items()}
    return found


def shares(alone):
    """{output: {input: u_i² / Σ u_j²}} from :func:`contributions` (per element for array
    outputs); an output no input moves gets no shares."""
    result = {}
    for key in next(iter(alone.values())):
        squares = {name: np.square(u[key]) for name, u in alone.items()}
        total = sum(squares.values())
        with np.errstate(invalid="ignore", divide="ignore"):
            result[key] = {name: np.where(total > 0, square / total, np.nan)
                           for name, square in squares.items()}
    return result
