"""Noise models: what a term's reduction of the residual is judged against, named in every
verdict. One per layout of the samples; the measurement chooses the one its data support.

- :class:`PureError`: repeated samples (target x direction groups with at least
  ``judge.MIN_PURE_DOF`` degrees of freedom). The extra-sum-of-squares F test against their
  within-group scatter (Draper & Smith, Applied Regression Analysis, 3rd ed., §2.1 and
  §6.1): a large effect is named however much unmodelled per-target shape is left.
- :class:`ResidualMeanSquare`: no repeats; the larger model's residual mean square (the
  partial F test); the noise is estimated from the scatter between neighbouring samples.
- :class:`Coloured`: a serially correlated residual (tracking traces): the F test with the
  sample count replaced by the effective count n / τ (:mod:`feedaxis.stats.coloured`).
"""
from __future__ import annotations

import numpy as np
from scipy import stats

from . import judge
from .coloured import autocorrelation_time
from .judge import Test


def _rss(values):
    return float(values @ values)


def _f_test(rss_before, rss_after, extra, denominator, dof, name):
    extra = max(int(extra), 1)
    statistic = max(rss_before - rss_after, 0.0) / extra / max(denominator, 1e-300)
    return Test(float(statistic), (extra, dof), float(stats.f.sf(statistic, extra, dof)), name)


class PureError:
    """The scatter of repeated samples: ``layout`` holds the repeat groups."""

    name = "F test against the pure error of repeated samples"
    source = "scatter of repeated samples"

    def __init__(self, layout):
        self.layout = layout

    def extra_ss_test(self, before_um, after_um, extra, n_free_after):
        """F test of ``extra`` parameters that took the residual from before to after: the
        pure error of the larger model, its degrees of freedom reduced by that model's
        parameters (some may vary within a group)."""
        dof = max(self.layout.pure_dof - n_free_after, 1)
        return _f_test(_rss(before_um), _rss(after_um), extra,
                       self.layout.pure_error_ss(after_um) / dof, dof, self.name)

    def estimate_um(self, residual_um):
        """(σ (µm), source): the pooled standard deviation within the groups."""
        return float(np.sqrt(self.layout.pure_error_ss(residual_um) / self.layout.pure_dof)), \
            self.source

    def error_scale(self, result):
        """√(pure-error variance / residual variance): turns the fit's standard errors (from
        its residual, unmodelled shape included) into ones resting on the repeatability."""
        statistics = result.statistics
        residual_variance = (statistics.rms_um**2 * statistics.n_points
                             / max(statistics.n_points - statistics.n_free, 1))
        pure_variance = (self.layout.pure_error_ss(result.residual_um)
                         / max(self.layout.pure_dof - statistics.n_free, 1))
        return float(np.sqrt(pure_variance / residual_variance)) if residual_variance > 0 else 1.0


class ResidualMeanSquare:
    """No repeats: the residual mean square; ``order`` sorts the samples along the test
    (run or time, then position) for the noise estimate."""

    name = "partial F test against the residual mean square (no repeats)"
    source = "point-to-point scatter along the travel"

    def __init__(self, order):
        self.order = order

    def extra_ss_test(self, before_um, after_um, extra, n_free_after):
        dof = max(after_um.size - n_free_after, 1)
        return _f_test(_rss(before_um), _rss(after_um), extra, _rss(after_um) / dof, dof,
                       self.name)

    def estimate_um(self, residual_um):
        """(σ (µm), source): the median absolute successive difference along the test
        (robust, scaled to a standard deviation); short-wave structure left in the residual
        makes it an upper bound."""
        steps = np.diff(residual_um[self.order])
        return (float(judge.MAD_TO_SIGMA * np.median(np.abs(steps - np.median(steps)))
                      / np.sqrt(2)), self.source)

    def error_scale(self, result):
        return 1.0


class Coloured:
    """A serially correlated residual: the effective sample count n / τ."""

    name = "F test with the effective sample count n/τ (serially correlated noise)"

    def extra_ss_test(self, before_um, after_um, extra, n_free_after):
        """F test of ``extra`` parameters with n replaced by n / τ, τ the integrated
        autocorrelation time of the larger model's residual (for a smooth regressor the
        variance of a least-squares coefficient grows by τ under coloured noise)."""
        rss_before, rss_after = _rss(before_um), _rss(after_um)
        extra = max(int(extra), 1)
        n_effective = after_um.size / autocorrelation_time(after_um)
        dof = n_effective - (n_free_after - extra) - extra
        if dof < 1 or rss_after <= 0.0:
            p_value = 0.0 if rss_after <= 0.0 < rss_before else 1.0
            return Test(float("inf") if p_value == 0.0 else 0.0, (extra, max(dof, 0.0)),
                        p_value, self.name)
        return _f_test(rss_before, rss_after, extra, rss_after / dof, float(dof), self.name)

    def estimate_um(self, residual_um):
        """(σ (µm), source): the RMS of the residual left, its autocorrelation time named."""
        tau = autocorrelation_time(residual_um)
        return (float(np.sqrt(np.mean(residual_um ** 2))),
                f"residual left after the effects and structures found (autocorrelation time "
                f"{tau:.1f} samples)")

    def error_scale(self, result):
        return 1.0
