"""The tests the diagnosis decides by: the family-wise policy, lack of fit, serial
correlation, outliers, repeat groups and the test's clock.

- Repeat groups are samples at one target and one approach direction
  (:func:`feedaxis.iso230.target_groups`); their within-group scatter is the *pure error*
  (:class:`feedaxis.stats.noise.PureError` tests against it).
- ``FAMILY_ALPHA`` is the family-wise error rate of a whole diagnosis under the complete
  null, for every kind of measurement. It is split equally over the stages the
  measurement's diagnosis runs (positioning: drift, effects, structures, lack of fit;
  tracking: effects, structures); at each selection step the best of the m terms tried is
  accepted when p < FAMILY_ALPHA / stages / m (Bonferroni; a search whose p-value is already
  family-wise over its trials counts once). Later steps only run once an earlier one has
  passed, so they add nothing to the error under the complete null.
- The clock is ``time_s`` (hours) when present, else run number plus the sample's place in
  its run: a drift across the test is tested even without time stamps.
- Outliers: each sample against the others of its group (leave-one-out mean, after a drift
  along the clock is taken out), else against its four neighbours along the travel, scaled
  by the median absolute deviation; flagged beyond the two-sided Gaussian quantile at
  OUTLIER_ALPHA / n (Bonferroni over the samples). Repeated with the flagged samples left
  out of the means, so a spike does not drag its neighbours over the limit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..iso230 import compact_index, target_groups
from .distributions import norm_isf, norm_sf
from .wording import p_text


FAMILY_ALPHA = 0.001
OUTLIER_ALPHA = 0.001
MIN_PURE_DOF = 10
MAX_OUTLIER_PASSES = 5
MAD_TO_SIGMA = 1.4826
TINY_UM = 1e-12  # far below any measurement (1 fm): a scale under it is rounding
BLOCK_ROWS = 1 << 16  # rows per block of a sum over the samples
MAX_NEWTON_STEPS = 100
MAX_HALVINGS = 30


@dataclass(frozen=True)
class Layout:
    """How a case was sampled: repeat groups, the clock, the first data row."""

    groups: np.ndarray
    n_groups: int
    clock: np.ndarray | None
    clock_unit: str | None

    @classmethod
    def of(cls, positioning, clusters=None):
        groups = target_groups(positioning, clusters)
        clock, unit = clock_of(positioning)
        return cls(groups, int(groups.max()) + 1, clock, unit)

    @property
    def sizes(self):
        return np.bincount(self.groups, minlength=self.n_groups)

    @property
    def pure_dof(self):
        return int(self.groups.size - self.n_groups)

    @property
    def has_repeats(self):
        return self.pure_dof >= MIN_PURE_DOF

    def group_means(self, values):
        """Mean of ``values`` in each sample's group, per sample."""
        return (np.bincount(self.groups, values, self.n_groups) / self.sizes)[self.groups]

    def subset(self, keep):
        """The layout of the samples ``keep`` (boolean mask), groups renumbered."""
        _, groups = np.unique(self.groups[keep], return_inverse=True)
        clock = None if self.clock is None else self.clock[keep]
        return Layout(compact_index(groups.ravel()), int(groups.max()) + 1, clock,
                      self.clock_unit)

    @property
    def clock_varies_within_groups(self):
        if self.clock is None or not self.has_repeats:
            return False
        return bool(np.ptp(self.clock - self.group_means(self.clock)) > 0)


def clock_of(positioning):
    """(clock per sample, unit): hours from ``time_s``, else run + place in the run (the
    k-th of a run's m samples in row order at run + k / m), every run at once through one
    stable sort by run (a pass over the samples per run took 28 s at 10^7 samples in
    5,000 runs)."""
    if positioning.time_s is not None and np.ptp(positioning.time_s) > 0:
        return positioning.time_s / 3600.0, "h"
    if positioning.run is None or np.ptp(positioning.run) == 0:
        return None, None
    order = np.argsort(positioning.run, kind="stable")
    run = positioning.run[order]
    starts = np.flatnonzero(np.concatenate(([True], run[1:] != run[:-1])))
    counts = np.diff(np.append(starts, run.size))
    place = np.arange(run.size) - np.repeat(starts, counts)
    clock = np.empty(run.size)
    clock[order] = run.astype(float) + place / np.repeat(counts, counts)
    return clock, "run"


@dataclass(frozen=True)
class Test:
    """One F test: statistic, degrees of freedom, p-value and which denominator was used."""

    statistic: float
    dof: tuple
    p_value: float
    name: str
    symbol: str = "F"

    def to_json(self):
        return {"test": self.name, "statistic": self.symbol, self.symbol: self.statistic,
                "dof": list(self.dof), "p_value": self.p_value}

    def describe(self):
        """The test in one phrase, e.g. ``F(2, 2497) = 2.78e+03, p < 1e-300``."""
        p_value = p_text(self.p_value)
        if self.symbol == "F":
            return (f"F({self.dof[0]:.4g}, {self.dof[1]:.4g}) = {self.statistic:.3g}, "
                    f"{p_value}")
        if self.symbol == "ratio":
            return f"{p_value}, family-wise over the frequencies searched"
        return f"{self.symbol} = {self.statistic:.3g} over {self.dof[1]} samples, {p_value}"


def serial_correlation_test(residual_um):
    """Von Neumann ratio test of a residual in the order the samples were taken: smooth
    structure or correlated noise left in it makes successive differences small against
    its variance.

    The ratio η = Σ(Δr)² / Σ(r - r̄)² is 2 for white noise with variance 4/n asymptotically
    (von Neumann 1941, Ann. Math. Stat. 12:367); reported as a z statistic.
    """
    residual = np.asarray(residual_um, dtype=float)
    centred = residual - residual.mean()
    ratio = float(np.sum(np.diff(residual) ** 2) / max(centred @ centred, 1e-300))
    z = (2.0 - ratio) / (2.0 / np.sqrt(residual.size))
    return Test(float(z), (1, residual.size), float(norm_sf(z)),
                "von Neumann ratio test in the order taken (no replicates)", "z")


def accepts(p_value, tried, stages, alpha=FAMILY_ALPHA):
    """Bonferroni at one selection step of one of ``stages`` stages: the best of ``tried``
    terms passes."""
    return p_value < alpha / max(stages, 1) / max(tried, 1)


def outlier_rows(layout, position_mm, residual_um, alpha=OUTLIER_ALPHA):
    """Indices (0-based) of isolated samples far outside the scatter of their neighbours."""
    n = residual_um.size
    flagged = np.zeros(n, dtype=bool)
    if n < 8:
        return np.flatnonzero(flagged)
    limit = norm_isf(alpha / (2 * n))
    if layout.has_repeats:  # the drift is fitted robustly once, to every sample
        residual_um = residual_um - _robust_drift(layout, residual_um)
    for _ in range(MAX_OUTLIER_PASSES):
        if layout.has_repeats:
            deviation = _against_group(layout, residual_um, ~flagged)
        else:
            deviation = _against_neighbours(position_mm, residual_um, ~flagged)
        scale = MAD_TO_SIGMA * np.nanmedian(np.abs(deviation[~flagged]))
        with np.errstate(invalid="ignore"):
            now = np.abs(deviation) > limit * scale if scale > 0 else flagged
        if np.array_equal(now, flagged):
            break
        flagged = now
    return np.flatnonzero(flagged)


def _against_group(layout, residual_um, valid):
    """Deviation of each sample (its drift removed) from the mean of the other valid
    samples of its group, over its standard deviation in noise units (√(1 + 1/(m - 1)));
    NaN where the group has no other valid sample."""
    weights = valid.astype(float)
    sizes = np.bincount(layout.groups, weights, layout.n_groups)[layout.groups]
    totals = np.bincount(layout.groups, residual_um * weights, layout.n_groups)[layout.groups]
    others = sizes - weights
    single = others < 1
    others = np.where(single, 1.0, others)
    deviation = np.where(single, np.nan, residual_um - (totals - residual_um * weights) / others)
    return deviation / np.sqrt(1.0 + 1.0 / others)


def _robust_drift(layout, residual_um):
    """A quadratic drift along the clock, fitted within the groups with a soft-L1 loss."""
    if not layout.clock_varies_within_groups:
        return np.zeros_like(residual_um)
    within = drift_basis(layout.clock)
    for column in within.T:  # in place: no second samples x 2 array beside the fit's own
        column -= layout.group_means(column)
    target = residual_um - layout.group_means(residual_um)
    scale = MAD_TO_SIGMA * np.median(np.abs(target))
    if not scale > TINY_UM:  # the groups agree to rounding: any loss scale will do, and a
        scale = 1.0          # tiny one would underflow (s² = 0) inside the loss
    return within @ soft_l1_line(within, target, scale)


def soft_l1_line(basis, target, scale, block=BLOCK_ROWS):
    """Coefficients c minimising Σ 2 s² (√(1 + (b_i·c - t_i)² / s²) - 1) (SciPy's
    ``soft_l1`` loss at ``f_scale`` s, a convex pseudo-Huber loss) for the few columns of
    ``basis``: Newton's method from zero with the exact gradient and Hessian, halving a
    step that raises the loss, until the step is at rounding. Every sum runs over
    blocks of ``block`` rows, so nothing the size of the samples is allocated (SciPy's
    trust region held about ten copies of the samples: the fit's peak at 10^6 samples)."""
    coefficients = np.zeros(basis.shape[1])
    loss, gradient, hessian = _soft_l1_sums(basis, target, scale, coefficients, block)
    for _ in range(MAX_NEWTON_STEPS):
        step = np.linalg.lstsq(hessian, gradient, rcond=None)[0]
        for _ in range(MAX_HALVINGS):
            trial = coefficients - step
            trial_loss, trial_gradient, trial_hessian = _soft_l1_sums(basis, target, scale,
                                                                      trial, block)
            if trial_loss <= loss + 1e-12 * loss:  # not higher, to the sums' rounding
                break
            step = step / 2
        else:
            return coefficients
        done = np.all(np.abs(trial - coefficients) <= 1e-13 * np.maximum(1.0, np.abs(trial)))
        coefficients, loss, gradient, hessian = trial, trial_loss, trial_gradient, trial_hessian
        if done:
            break
    return coefficients


def _soft_l1_sums(basis, target, scale, coefficients, block):
    """(loss, gradient, Hessian) of :func:`soft_l1_line` at ``coefficients``, summed over
    blocks of rows."""
    size = basis.shape[1]
    loss, gradient, hessian = 0.0, np.zeros(size), np.zeros((size, size))
    for start in range(0, target.size, block):
        rows = basis[start:start + block]
        residual = (rows @ coefficients - target[start:start + block]) / scale
        root = np.sqrt(1.0 + residual * residual)
        loss += 2.0 * scale * scale * float(np.sum(root - 1.0))
        gradient += rows.T @ (2.0 * scale * residual / root)
        hessian += (rows.T * (2.0 / root**3)) @ rows
    return loss, gradient, hessian


def _against_neighbours(position_mm, residual_um, valid):
    """Deviation from the mean of the two valid neighbours on each side along the travel,
    over its standard deviation in noise units (√(1 + 1/4))."""
    order = np.argsort(position_mm, kind="stable")
    kept = order[valid[order]]
    padded = np.pad(residual_um[kept], 2, mode="reflect")
    neighbours = (padded[:-4] + padded[1:-3] + padded[3:-1] + padded[4:]) / 4.0
    # every sample (valid or not) against the neighbours of the nearest valid sample
    nearest = np.clip(np.searchsorted(position_mm[kept], position_mm[order]), 0, kept.size - 1)
    deviation = np.empty_like(residual_um)
    deviation[order] = residual_um[order] - neighbours[nearest]
    deviation[kept] = residual_um[kept] - neighbours
    return deviation / np.sqrt(1.25)


def drift_basis(clock, out=None):
    """Linear and quadratic drift along the clock (columns centred and scaled to ±1),
    written into ``out`` (samples x 2) where given, without a sample-sized temporary."""
    span = np.ptp(clock) or 1.0
    out = np.empty((clock.size, 2)) if out is None else out
    scaled, square = out[:, 0], out[:, 1]
    np.subtract(clock, clock.min(), out=scaled)
    np.subtract(np.divide(np.multiply(2.0, scaled, out=scaled), span, out=scaled), 1.0,
                out=scaled)
    np.square(scaled, out=square)
    np.subtract(square, np.mean(square), out=square)
    return out
