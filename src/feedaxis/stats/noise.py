"""Noise models: what a term's reduction of the residual is judged against, named in every
verdict. The measurement chooses the one its samples support.

Each model has a ``label`` that both its test (``name``) and its noise estimate (the
source :meth:`estimate_um` gives) carry, so the noise a diagnosis prints and the test it
decided by always name the same model.

- :class:`PureError`: repeated samples. The extra-sum-of-squares F test against their
  within-group scatter (Draper & Smith, Applied Regression Analysis, 3rd ed., §2.1 and
  §6.1): a large effect is named however much unmodelled per-target shape is left. The
  groups are the repeat groups (target x direction) of a test with repeated runs, or, in a
  single pass each way, the targets, with a reversal between the + and - readings allowed
  (constant, or linear along the travel where the pairs show it: a drift linear in time
  over the two passes is the same): the readings at a target are then replicates.
- :class:`ResidualMeanSquare`: no replicates; the larger model's residual mean square (the
  partial F test), the noise estimated from the scatter between neighbouring samples.
- :class:`Serial`: noise correlated along the test (air turbulence and slow drift in laser
  data, servo and encoder noise in a trace). Each test fits an autoregressive model to the
  noise part of the larger model's residual (within the replicate groups where there are
  replicates) in the order the samples were taken, when the Ljung-Box test rejects
  whiteness at 1 % (over pairs of samples in different groups where there are replicates:
  deviations from a group mean are correlated within the group by construction; the AR
  model by conditional least squares, the order by BIC);
  when it is white, the underlying model above decides; otherwise the term's explained sum of squares per parameter is set
  against the noise power at the term's own frequencies, σ²_eff = Σ S(f)|C(f)|² / Σ|C(f)|²
  (S the AR spectrum, C the spectrum of the fitted term): for a smooth term that is the
  long-run variance S(0), for white noise σ² (the plain F test). The AR model's persistence
  Σφ is raised two standard errors for these decisions, as its estimate from a few hundred
  samples is biased low and the tests at low frequencies would be liberal.
- :class:`SerialPairs`: one pass each way, its noise looked for along the travel in the
  half-differences of the pairs; the pairs' F test where they are white.
- :class:`Coloured`: a serially correlated trace judged with the effective sample count
  n / τ (:mod:`feedaxis.stats.coloured`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from . import judge
from .coloured import (Autoregression, KeptByContent, autocorrelation_time, block_variance,
                       least_squares_autoregression, ljung_box_p_value, noise_floor_um)
from .distributions import f_sf
from .judge import Test

SERIAL_MAX_ORDER = 5
SERIAL_KEPT = 8  # AR models kept by residual (Serial.autoregression)
SERIAL_ALPHA = 0.01  # the Ljung-Box test over SERIAL_MAX_ORDER lags: white noise taken for
#                      correlated in 1 % of tests, and only then an AR model of order >= 1
SPECTRA_BYTES = 2 ** 27  # the FFTs spectral_gram holds at a time (128 MB)


def _rss(values):
    return float(values @ values)


def _f_test(rss_before, rss_after, extra, denominator, dof, name):
    extra = max(int(extra), 1)
    dof = max(dof, 1)
    statistic = max(rss_before - rss_after, 0.0) / extra / max(denominator, 1e-300)
    return Test(float(statistic), (extra, dof), float(f_sf(statistic, extra, dof)), name)


class PureError:
    """Replicates: ``groups`` (index per sample) and, optionally, ``within`` columns (samples
    x k) fitted inside every group alike (a reversal between + and - readings, constant or
    linear along the travel)."""

    def __init__(self, groups, within=None, paired=False, measured_um=None):
        self.groups = np.asarray(groups)
        self.n_groups = int(self.groups.max()) + 1
        self.sizes = np.bincount(self.groups, minlength=self.n_groups)
        self.within = None if within is None else self._centred(
            np.asarray(within, float).reshape(self.groups.size, -1))
        rank = 0 if self.within is None else int(np.linalg.matrix_rank(self.within))
        self.dof = int(self.groups.size - self.n_groups - rank)
        self.paired = paired
        self.measured = None if measured_um is None else self.noise_part(measured_um)
        reversal = "a constant reversal" if rank <= 1 else "a reversal linear along the travel"
        self.label = "+ and - readings at each target" if paired else "repeated samples"
        self.name = (f"F test against the scatter of the {self.label} (one pass each way, "
                     f"{reversal} allowed)" if paired else
                     f"F test against the pure error of {self.label}")
        self.source = (f"scatter of the {self.label} about {reversal}" if paired
                       else f"scatter of {self.label}")

    def group_means(self, values):
        """Mean of ``values`` in each sample's group, per sample."""
        return (np.bincount(self.groups, values, self.n_groups) / self.sizes)[self.groups]

    def _centred(self, values):
        if values.ndim == 1:
            means = self.group_means(values)
            return np.subtract(values, means, out=means)  # no second sample-sized array
        return np.column_stack([self._centred(column) for column in values.T])

    def noise_part(self, residual_um):
        """The residual within the groups, the within columns fitted: its noise alone,
        whatever structure sits between the groups (µm, per sample)."""
        within = self._centred(residual_um)
        if self.within is not None:
            within = within - self.within @ np.linalg.lstsq(self.within, within, rcond=None)[0]
        return within

    def pure_ss(self, residual_um):
        """Sum of squares of the residual within the groups, the within columns fitted (µm²)."""
        within = self.noise_part(residual_um)
        return float(within @ within)

    def extra_ss_test(self, before_um, after_um, extra, n_free_after):
        """F test of ``extra`` parameters that took the residual from before to after: the
        pure error of the larger model, its degrees of freedom reduced by that model's
        parameters (some may vary within a group) unless the model left the noise part of
        the samples (``measured_um``) as it was: every term then constant in a group or
        one of the ``within`` columns, the pure error the data's own (at 11 targets in one
        pass each way, the two parameters of a lead error took 2 of 9 degrees of
        freedom)."""
        after = self.noise_part(after_um)
        untouched = self.measured is not None and np.allclose(
            after, self.measured, rtol=0.0, atol=1e-9 * max(np.abs(self.measured).max(), 1e-12))
        dof = self.dof if untouched else max(self.dof - n_free_after, 1)
        return _f_test(_rss(before_um), _rss(after_um), extra, float(after @ after) / dof,
                       dof, self.name)

    def shape_test(self, before_um, after_um, extra, n_free_after):
        """The test of a term with a shape of its own (a sinusoid, a trend): fitted to an
        irregular error between the groups, any such shape explains some of it, so it must
        stand out against the pure error and against the residual mean square (the lack of
        fit included) alike: the larger p-value of the two."""
        tests = (self.extra_ss_test(before_um, after_um, extra, n_free_after),
                 ResidualMeanSquare(None).extra_ss_test(before_um, after_um, extra,
                                                         n_free_after))
        return max(tests, key=lambda test: test.p_value)

    def estimate_um(self, residual_um):
        """(σ (µm), source): the pooled standard deviation within the groups."""
        return float(np.sqrt(self.pure_ss(residual_um) / max(self.dof, 1))), self.source

    def error_scale(self, result):
        """√(pure-error variance / residual variance): turns the fit's standard errors (from
        its residual, unmodelled shape included) into ones resting on the replicates."""
        statistics = result.statistics
        residual_variance = (statistics.rms_um**2 * statistics.n_points
                             / max(statistics.n_points - statistics.n_free, 1))
        pure_variance = self.pure_ss(result.residual_um) / max(self.dof - statistics.n_free, 1)
        return float(np.sqrt(pure_variance / residual_variance)) if residual_variance > 0 else 1.0

    def lack_of_fit_test(self, residual_um, n_between, n_within):
        """Lack-of-fit F test: the group means of the residual against the pure error, with
        ``n_between`` parameters fitted to the group means and ``n_within`` (a drift)
        within."""
        means = self.group_means(residual_um)
        lof_dof = max(self.n_groups - n_between, 1)
        pure_dof = max(self.dof - n_within, 1)
        statistic = (float(means @ means) / lof_dof) / max(self.pure_ss(residual_um) / pure_dof,
                                                           1e-300)
        return Test(statistic, (lof_dof, pure_dof),
                    float(f_sf(statistic, lof_dof, pure_dof)),
                    f"lack-of-fit F test against the {self.source}")


class ResidualMeanSquare:
    """No replicates: the residual mean square; ``order`` sorts the samples in the order they
    were taken (run or time, then position) for the noise estimate."""

    label = "no replicates"
    name = f"partial F test against the residual mean square ({label})"
    source = f"point-to-point scatter along the test ({label})"

    def __init__(self, order):
        self.order = order

    def noise_part(self, residual_um):
        """Without replicates the residual is all the data say of the noise."""
        return residual_um

    def extra_ss_test(self, before_um, after_um, extra, n_free_after):
        dof = max(after_um.size - n_free_after, 1)
        return _f_test(_rss(before_um), _rss(after_um), extra, _rss(after_um) / dof, dof,
                       self.name)

    shape_test = extra_ss_test

    def estimate_um(self, residual_um):
        """(σ (µm), source): the median absolute successive difference in the order taken
        (robust, scaled to a standard deviation); short-wave structure left in the residual
        makes it an upper bound."""
        steps = np.diff(residual_um[self.order])
        return (float(judge.MAD_TO_SIGMA * np.median(np.abs(steps - np.median(steps)))
                      / np.sqrt(2)), self.source)

    def error_scale(self, result):
        return 1.0


class _WhiteUnlessCorrelated:
    """What a noise model that may find correlation shares: where its ``autoregression``
    is white, the ``white`` model's shape test and error scale."""

    def shape_test(self, before_um, after_um, extra, n_free_after):
        """The white model's shape test where the noise is white, else the serial test."""
        if self.autoregression(after_um).order == 0:
            return self.white.shape_test(before_um, after_um, extra, n_free_after)
        return self.extra_ss_test(before_um, after_um, extra, n_free_after)

    def error_scale(self, result):
        if self.autoregression(result.residual_um).order == 0:
            return self.white.error_scale(result)
        return 1.0


class Serial(_WhiteUnlessCorrelated):
    """Noise possibly correlated along the test: ``order`` sorts the samples in the order
    they were taken; ``white`` decides where the residual shows no correlation."""

    def __init__(self, order, white):
        self.order, self.white, self.label = order, white, white.label
        self.reordered = bool(np.any(np.diff(order) != 1))  # not the samples' own order
        self._fitted = KeptByContent(SERIAL_KEPT)
        self.name = (f"{white.name}; where the residual is serially correlated, against the "
                     "noise power at the term's frequencies (AR noise model, order by BIC)")

    def autoregression(self, residual_um):
        """The AR model of the residual's noise part (within the replicate groups where
        there are replicates, so structure between targets is not taken for correlated
        noise) in the order taken: white unless the Ljung-Box test rejects whiteness at
        ``SERIAL_ALPHA``, then of order 1 to ``SERIAL_MAX_ORDER`` by conditional least
        squares and BIC. The last few are kept by the residual's content: a fit's
        residual is tested and then weighs its uncertainties (a third of a second each
        at 10^6 samples)."""
        return self._fitted.get(residual_um, self._autoregression)

    def _autoregression(self, residual_um):
        """:meth:`autoregression`, computed; the noise part and its groups put in the order
        taken only where that is not the samples' own (two sample-sized copies saved)."""
        ordered, groups = self.white.noise_part(residual_um), getattr(self.white, "groups", None)
        if self.reordered:
            ordered, groups = ordered[self.order], None if groups is None else groups[self.order]
        if ljung_box_p_value(ordered, SERIAL_MAX_ORDER, groups) >= SERIAL_ALPHA:
            spread = block_variance(ordered)
            return Autoregression(np.zeros(0), spread, spread)
        return least_squares_autoregression(ordered, SERIAL_MAX_ORDER)

    def extra_ss_test(self, before_um, after_um, extra, n_free_after):
        """The white model's test where the noise part of the larger model's residual is
        white, else the spectral test against its AR model with the persistence raised two
        standard errors (:meth:`~feedaxis.stats.coloured.Autoregression.cautious`)."""
        noise = self.autoregression(after_um)
        if noise.order == 0:
            return self.white.extra_ss_test(before_um, after_um, extra, n_free_after)
        return self._spectral_test(noise.cautious(), before_um, after_um, extra, n_free_after)

    def _spectral_test(self, noise, before_um, after_um, extra, n_free_after):
        """F test of the term (before - after) against ``noise``'s power at its frequencies."""
        effective = noise_power_at(noise, (before_um - after_um)[self.order])
        return _f_test(_rss(before_um), _rss(after_um), extra, effective,
                       after_um.size - n_free_after - noise.order,
                       f"F test against the serially correlated noise at the term's "
                       f"frequencies (AR({noise.order}), neighbours correlated "
                       f"{noise.lag_one():.2f})")

    def estimate_um(self, residual_um):
        """(σ (µm), source): the white model's estimate, or the marginal standard deviation of
        the correlated noise, its correlation named."""
        noise = self.autoregression(residual_um)
        if noise.order == 0:
            return self.white.estimate_um(residual_um)
        return (float(np.sqrt(noise.variance)),
                f"serially correlated along the test ({self.label}): AR({noise.order}), "
                f"neighbouring samples correlated {noise.lag_one():.2f}")

    def gram(self, jacobian, residual_um, variance):
        """J'ΣJ of the Jacobian (samples x parameters) under the noise of ``residual_um``:
        ``variance`` · J'J when it is white, else through the AR spectrum (the sandwich
        covariance's middle; Σ circulant, evaluated by FFT)."""
        noise = self.autoregression(residual_um)
        if noise.order == 0:
            return variance * (jacobian.T @ jacobian)
        return spectral_gram(jacobian.T[:, self.order] if self.reordered else jacobian.T,
                             noise.spectrum)


def noise_power_at(noise, *series):
    """σ²_eff = Σ S(f)|C(f)|² / Σ|C(f)|²: the power of ``noise`` (an AR model) at the
    frequencies of a term, C the spectra of its ``series`` (each in sample order, their
    powers added; zero-padded to the next power of two ≥ 2n)."""
    n_fft = 1 << int(np.ceil(np.log2(2 * series[0].size)))
    power = sum(np.abs(np.fft.rfft(values, n_fft)) ** 2 for values in series)
    power[1:-1] *= 2.0
    return float(noise.spectrum(n_fft) @ power / max(power.sum(), 1e-300))


def spectral_gram(columns, spectrum):
    """Σ_f S(f)|C(f)|²-weighted Gram matrix of ``columns`` (one row per column, in sample
    order): Re(C W Cᴴ) over the one-sided FFT C of each row zero-padded to the next power
    of two ≥ 2n, W the spectrum ``spectrum(n_fft) / n_fft`` with the inner frequencies
    doubled (a circulant Σ: J'ΣJ without forming Σ). The rows are transformed in blocks of
    as many as ``SPECTRA_BYTES`` holds, each transform weighted by √W, and each block's
    rows are multiplied by their own and every later row's transform: k transforms of k
    rows where the block holds them all (every fit's at 10^6 samples), k(k+1)/2 in the
    memory of two where it holds one (at 10^7 samples one transform is 270 MB)."""
    n_fft = 1 << int(np.ceil(np.log2(2 * columns.shape[1])))
    weights = spectrum(n_fft) / n_fft
    weights[1:-1] *= 2.0
    root = np.sqrt(weights)
    size, width = columns.shape[0], n_fft // 2 + 1
    held = max(SPECTRA_BYTES // (16 * width) - 1, 1)
    block = np.empty((min(held, size), width), dtype=complex)
    other = np.empty(width, dtype=complex) if held < size else None  # a later row's
    gram = np.empty((size, size))
    for start in range(0, size, held):
        stop = min(start + held, size)
        for row, column in zip(block, columns[start:stop]):
            _weighted_transform(column, root, row)
        # (re, im) interleaved: one real product sums both
        pairs = block[:stop - start].view(np.float64)
        for j in range(start, size):
            later = (pairs[j - start] if j < stop else
                     _weighted_transform(columns[j], root, other).view(np.float64))
            for i in range(start, min(j + 1, stop)):
                gram[i, j] = gram[j, i] = pairs[i - start] @ later
    return gram


def _weighted_transform(column, root, out):
    """The one-sided FFT of ``column`` zero-padded to ``2 * (out.size - 1)``, times
    ``root``, into ``out``."""
    np.fft.rfft(column, 2 * (out.size - 1), out=out)
    out *= root
    return out


SLOW_SHARE = 1.5  # the residual's RMS over its floor above which its slow part is named


class Coloured:
    """A serially correlated residual: the effective sample count n / τ."""

    label = "serially correlated noise"
    name = f"F test with the effective sample count n/τ ({label})"

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

    def shape_test(self, before_um, after_um, extra, n_free_after):
        return self.extra_ss_test(before_um, after_um, extra, n_free_after)

    def estimate_um(self, residual_um):
        """(σ (µm), source): the measurement's noise as the high-frequency floor of the
        residual left (:func:`~feedaxis.stats.coloured.noise_floor_um`: what no model of the
        motion carries), not its RMS: a slow model error would pass for noise there. The
        source names the RMS, its ratio to the floor and the autocorrelation time, and says
        that the slow part is noise or model error, which one record cannot tell apart."""
        floor_um = noise_floor_um(residual_um)
        rms_um = float(np.sqrt(np.mean(residual_um ** 2)))
        tau = autocorrelation_time(residual_um)
        slow = (f"; the residual left is {rms_um:.3g} µm RMS, {rms_um / floor_um:.3g}x the floor "
                f"(autocorrelation time {tau:.1f} samples): its slow part is coloured noise "
                "or a model error, which one record cannot tell apart"
                if floor_um > 0.0 and rms_um > SLOW_SHARE * floor_um else "")
        return (floor_um, f"{self.label}: the high-frequency floor of the residual left "
                          f"(sample-to-sample changes){slow}")

    def error_scale(self, result):
        return 1.0



PAIRS_MAX_ORDER = 2  # an AR model of a dozen or two half-differences: order 1 or 2
PAIRS_ALPHA = 0.05  # the von Neumann test of the half-differences: a dozen or two values
#                   detect slow noise poorly, and a false detection only makes the tests
#                   cautious (ρ = 0.8 nulls named a lead error in 9 % at 0.01, 5 % at 0.05)


class SerialPairs(_WhiteUnlessCorrelated):
    """One pass each way, read as target means and half-differences along the travel (the
    n targets in ``along`` order, each with one + and one - reading): slow noise in the
    readings (air, a drift) correlates both alike from target to target, a trend in the
    means included. Where the half-differences about the reversal show no serial
    correlation (the von Neumann ratio test, one-sided at ``PAIRS_ALPHA``) the ``pairs``
    decide (:class:`PureError`); else each term is judged
    against the AR noise of the half-differences (order by BIC, persistence raised two
    standard errors) at the term's own frequencies along the travel, its means and
    half-differences both. (The noise part in the order taken holds each half-difference
    twice, mirrored about the turn: no series for an AR model.)"""

    def __init__(self, pairs, direction, along):
        self.pairs = self.white = pairs
        self.along = np.asarray(along)
        self.plus = np.asarray(direction) > 0
        self.label, self.source = pairs.label, pairs.source
        self.name = (f"{pairs.name}; where their half-differences are serially correlated "
                     "along the travel, against their AR noise power at the term's "
                     "frequencies along the travel")

    def _halves(self, values):
        """(target means, half-differences) of per-sample ``values``, in ``along`` order."""
        groups, n = self.pairs.groups, self.pairs.n_groups
        plus = np.bincount(groups[self.plus], values[self.plus], n)
        minus = np.bincount(groups[~self.plus], values[~self.plus], n)
        return (plus + minus)[self.along] / 2, (plus - minus)[self.along] / 2

    def _noise_halves(self, residual_um):
        """The half-differences about the reversal, scaled to the pairs' degrees of
        freedom (µm)."""
        halves = self._halves(self.pairs.noise_part(residual_um))[1]
        return halves * np.sqrt(halves.size / max(self.pairs.dof, 1))

    def correlation(self, residual_um):
        """The von Neumann ratio test of the half-differences when it rejects whiteness at
        ``PAIRS_ALPHA``, else None."""
        test = judge.serial_correlation_test(self._noise_halves(residual_um))
        if test.p_value >= PAIRS_ALPHA:
            return None
        return replace(test, name="von Neumann ratio test of the half-differences along the "
                                  "travel")

    def autoregression(self, residual_um):
        """The AR model of the half-differences about the reversal (µm², a target mean's
        scale), white unless :meth:`correlation` finds them correlated."""
        halves = self._noise_halves(residual_um)
        if self.correlation(residual_um) is None:
            variance = float(np.mean(halves ** 2))
            return Autoregression(np.zeros(0), variance, variance)
        return least_squares_autoregression(halves, PAIRS_MAX_ORDER)

    def extra_ss_test(self, before_um, after_um, extra, n_free_after):
        noise = self.autoregression(after_um)
        if noise.order == 0:
            return self.pairs.extra_ss_test(before_um, after_um, extra, n_free_after)
        noise = noise.cautious()
        effective = noise_power_at(noise, *self._halves(before_um - after_um))
        return _f_test(_rss(before_um) / 2, _rss(after_um) / 2, extra, effective,
                       self.pairs.dof - n_free_after - noise.order,
                       f"F test against the serially correlated noise of the pairs along the "
                       f"travel at the term's frequencies (AR({noise.order}), neighbouring "
                       f"targets correlated {noise.lag_one():.2f})")

    def estimate_um(self, residual_um):
        """(σ of one reading (µm), source): the pairs' estimate, or the correlated noise's."""
        noise = self.autoregression(residual_um)
        if noise.order == 0:
            return self.pairs.estimate_um(residual_um)
        return (float(np.sqrt(2.0 * noise.variance)),
                f"{self.source}, serially correlated along the travel: AR({noise.order}), "
                f"neighbouring targets correlated {noise.lag_one():.2f}")
