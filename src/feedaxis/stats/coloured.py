"""Significance under serially correlated (coloured) noise.

Tracking residuals are far from white (encoder and servo noise is low-pass, a model error
is smooth in time), so a white-noise F test on 5,000 samples names effects that are not
there. The tests allow for the colour:

- nested models (an effect or a structure with ``k`` more parameters): the F test on the
  drop of the residual sum of squares with the sample count replaced by the effective count
  n / τ (:class:`feedaxis.stats.noise.Coloured`), τ the integrated autocorrelation time of
  the larger model's residual (:func:`autocorrelation_time`, Sokal's adaptive window; for a
  smooth regressor the variance of a least-squares coefficient grows by the factor τ under
  coloured noise: the noise's long-run variance is τ·σ²);
- the noise model for the spectral tests (:func:`autoregression`, :func:`whitened`): an
  autoregressive filter (Yule-Walker, order by AIC up to ``MAX_AR_ORDER``) fitted to the
  noise's spectrum: the periodogram with its lines cut out (ordinates over ``LINE_RATIO``
  times the running median replaced by it), or for tracking records, robustly, the lower
  quartile, over half-overlapping Hann-tapered segments, of each frequency's periodogram
  ordinate (a disturbance present in fewer than three quarters of the segments, a burst,
  does not raise it), with the lines present throughout cut out likewise; a filter fitted
  to the plain periodogram follows a strong burst and notches it out of the residual it
  whitens (a 50 Hz burst 13,000x the noise floor was whitened away);
- a sinusoid of unknown frequency lasting the record (:func:`peak_p_value`): in the
  whitened residual's periodogram the largest ordinate over the mean of the others is Exp(1)
  under the null at each Fourier frequency, and the family-wise p-value over the M searched
  frequencies is 1 - (1 - e^{-ratio})^M (Fisher's max-periodogram argument). A local noise
  level from a running median was tried first: its own scatter fattens the tail, 15 % false
  alarms at p < 0.001 on pure coloured noise;
- a sinusoid during part of the record (:func:`short_time_peak`): the whitened residual,
  clipped at ``CLIP_SIGMA`` robust standard deviations (a single-sample spike would otherwise
  raise every ordinate of its window), is cut into half-overlapping windows of 64 samples
  up to a quarter of the record (doubling); each window's periodogram ordinates (DC and
  Nyquist left out) over their common level (median / ln 2 over all windows of that length:
  robust to the burst itself) are Exp(1) under the null, and the family-wise p-value of the
  largest is M e^{-ratio} over all M ordinates tried (Bonferroni; overlapping windows make
  it conservative). :func:`locate_sinusoid` then finds the burst's start, end and frequency
  by least squares (a gated sinusoid, its edges searched over every pair of samples).

Single-sample spikes (:func:`spikes`) are told from the record by each sample's departure
from the cubic through its two neighbours on each side (which follows a smooth signal: a
sinusoid of 20 samples per period to 0.2 %, where the mean of the neighbours misses it by
12 %), against the median absolute departure, at the Gaussian quantile of ``alpha`` / n
(Bonferroni over the samples): the largest first, replaced by its cubic, until none is left;
a sample is a spike only when its neighbours agree once it is replaced (a kink moves
several); the two samples at each end are not judged.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
import scipy
from numpy.lib.stride_tricks import sliding_window_view

from .distributions import chi2_ppf, chi2_sf, norm_isf

SOKAL_WINDOW = 5.0
SOKAL_FIRST_SHARE = 8  # the window is first sought over lags up to n / 8
MAX_AR_ORDER = 10
LINE_RATIO = 20.0
LINE_LEVEL_BINS = 41
SEGMENT_LINE_BINS = 9  # the running median's width across the segments' coarser spectrum
SEGMENT = 256  # samples per segment of the robust noise spectrum (fewer in short records)
MIN_SEGMENT = 32
NOISE_QUANTILE = 0.25
MIN_ROBUST_SEGMENTS = 8
MIN_WINDOW = 64  # the shortest window of the short-time periodogram
CLIP_SIGMA = 5.0  # a Gaussian sample beyond it: 6e-7 (0.3 % of 5,000-sample records)
GATE_GRID = 400  # coarse grid of a burst's edges (points over the record)
TAUS_KEPT = 8


class KeptByContent:
    """The last ``size`` results of a function of one array, kept by the array's content
    (its shape and a SHA-1 digest: 5 ms at 10^6 samples, against the FFTs or regressions a
    residual asked for again would cost; a key among the arrays of one analysis, not a
    guard against crafted collisions: on a processor with SHA instructions 2.5x faster
    than the BLAKE2b digest it replaced); the oldest leaves first."""

    def __init__(self, size):
        self.size, self._kept = size, {}

    def __len__(self):
        return len(self._kept)

    def get(self, values, compute):
        """``compute(values)`` as kept for an array of the same content, else computed and
        kept (``values`` as contiguous floats)."""
        values = np.ascontiguousarray(values, dtype=float)
        key = (values.shape, hashlib.sha1(values.data, usedforsecurity=False).digest())
        if key not in self._kept:
            while len(self._kept) >= self.size:
                self._kept.pop(next(iter(self._kept)))
            self._kept[key] = compute(values)
        return self._kept[key]


_KEPT_TAUS = KeptByContent(TAUS_KEPT)


def _autocovariance(residual, lags=None):
    """Biased autocovariance at lags 0..``lags`` (default n − 1) of the mean-removed residual
    (by FFT, zero-padded to a length of small prime factors at least n + ``lags``, so no
    lag wraps: 2n itself may hold a large prime, 20x slower at n = 24,799)."""
    from scipy.fft import next_fast_len

    centred = np.asarray(residual, dtype=float) - np.mean(residual)
    n = centred.size
    lags = n - 1 if lags is None else min(lags, n - 1)
    length = next_fast_len(max(n + lags, 1), real=True)
    spectrum = np.fft.rfft(centred, length)
    return np.fft.irfft(spectrum * np.conj(spectrum), length)[:lags + 1] / n


def autocorrelation_time(residual):
    """Integrated autocorrelation time τ = 1 + 2 Σ ρ(k), summed up to the first lag
    k >= 5 τ(k) (Sokal's adaptive window); 1 for white noise. The last ``TAUS_KEPT`` are
    kept by the residual's content (:class:`KeptByContent`; two FFTs saved each time): a
    fit's residual is asked for by its uncertainties, its check for a measurement delay,
    the diagnosis's tests and its noise estimate."""
    return _KEPT_TAUS.get(residual, _autocorrelation_time)


def _autocorrelation_time(residual):
    """τ from the lags up to n / ``SOKAL_FIRST_SHARE`` first (transforms of about 1.1 n
    points, not 2 n: at n = 500,000 each 5 ms, not 25), from all n only when the window
    does not close within them: the first lag where it closes is the same either way."""
    n = np.size(residual)
    for lags in sorted({max(n // SOKAL_FIRST_SHARE, 1), n - 1}):
        autocovariance = _autocovariance(residual, lags)
        if autocovariance[0] <= 0.0:
            return 1.0
        rho = autocovariance / autocovariance[0]
        tau = 1.0 + 2.0 * np.cumsum(rho[1:])
        stop = np.flatnonzero(np.arange(1, autocovariance.size) >= SOKAL_WINDOW * tau)
        if stop.size:
            return float(max(tau[stop[0]], 1.0))
    return float(max(tau[-1], 1.0))


def _segment_length(n):
    """Samples per segment of the robust spectrum: ``SEGMENT``, shorter in short records
    (at least 8 segments), never under ``MIN_SEGMENT``; the whole record when shorter."""
    length = SEGMENT
    while length > MIN_SEGMENT and n < 4 * length:
        length //= 2
    return min(length, n)


def _robust_noise_autocovariance(centred, max_order):
    """Autocovariance of the noise at lags 0..max_order, from its robust spectrum.

    The Hann-tapered segments' periodograms estimate the spectrum smoothed by the taper;
    their inverse transform is the autocovariance times the taper's own autocorrelation
    (the lag window), divided out. The lower quartile of an Exp(1)-distributed ordinate is
    its mean times -ln(0.75) (χ²₁ at DC and Nyquist).
    """
    length = _segment_length(centred.size)
    taper = np.hanning(length + 2)[1:-1]
    segments = sliding_window_view(centred, length)[::max(length // 2, 1)]
    power = np.abs(np.fft.rfft(segments * taper, axis=1)) ** 2 / (taper @ taper)
    if len(segments) >= MIN_ROBUST_SEGMENTS:
        level = np.quantile(power, NOISE_QUANTILE, axis=0)
        factor = np.full(level.size, -np.log1p(-NOISE_QUANTILE))
        factor[[0, -1] if length % 2 == 0 else [0]] = chi2_ppf(NOISE_QUANTILE, 1)
        level = level / factor
    else:
        level = power.mean(axis=0)
    running = scipy.ndimage.median_filter(level, size=SEGMENT_LINE_BINS, mode="nearest")
    level = np.where(level > LINE_RATIO * running, running, level)
    lags = np.arange(max_order + 1)
    lag_window = np.array([taper[:length - k] @ taper[k:] for k in lags]) / (taper @ taper)
    return np.fft.irfft(level, length)[lags] / lag_window
def _noise_autocovariance(centred, max_order):
    """Autocovariance at lags 0..max_order from the periodogram with its lines cut out."""
    n = centred.size
    power = np.abs(np.fft.rfft(centred, 2 * n)) ** 2 / n
    level = scipy.ndimage.median_filter(power, size=LINE_LEVEL_BINS, mode="nearest")
    cleaned = np.where(power > LINE_RATIO * level, level, power)
    return np.fft.irfft(cleaned)[:max_order + 1]


@dataclass(frozen=True)
class Autoregression:
    """An autoregressive noise model x_k = Σ φ_j x_{k-j} + w_k: ``coefficients`` φ, the
    innovation variance σ²_w and the marginal variance γ(0) (µm²)."""

    coefficients: np.ndarray
    innovation_variance: float
    variance: float
    persistence_error: float = 0.0

    @property
    def order(self):
        return int(self.coefficients.size)

    def cautious(self, margin=2.0):
        """The model with its persistence Σφ raised by ``margin`` standard errors (capped
        below 1), the coefficients shifted alike: an upper bound of the noise power at low
        frequencies, where a few hundred samples understate it (a smooth term tested
        against the point estimate passed at p ~ 1e-5 on AR(1) nulls with ρ = 0.95)."""
        if self.order == 0 or self.persistence_error == 0.0:
            return self
        persistence = float(np.sum(self.coefficients))
        raised = min(persistence + margin * self.persistence_error, 0.5 * (1 + persistence),
                     0.999)
        shifted = self.coefficients + (raised - persistence) / self.order
        return Autoregression(shifted, self.innovation_variance, self.variance)

    def whiten(self, residual):
        """The innovations w_k of the mean-removed ``residual`` (the first p samples dropped)."""
        residual = np.asarray(residual, dtype=float) - np.mean(residual)
        innovations = residual.copy()
        for lag, coefficient in enumerate(self.coefficients, start=1):
            innovations[lag:] -= coefficient * residual[:-lag]
        return innovations[self.order:]

    def spectrum(self, n_fft):
        """Power spectral density per sample (µm²) at the ``n_fft // 2 + 1`` frequencies of
        a real FFT of length ``n_fft``: σ²_w / |1 - Σ φ_j e^{-2πijf}|²."""
        filter_response = np.fft.rfft(np.concatenate(([1.0], -self.coefficients)), n_fft)
        return self.innovation_variance / np.maximum(np.abs(filter_response) ** 2, 1e-300)

    def lag_one(self):
        """Correlation between neighbouring samples implied by the model."""
        if self.order == 0:
            return 0.0
        return float(self.coefficients[0] if self.order == 1 else
                     _lag_one_of(self.coefficients))


def _lag_one_of(coefficients):
    """ρ(1) of an AR(p) from its coefficients (the first Yule-Walker equation solved with
    the others, by a linear solve of the autocorrelations ρ(1..p))."""
    order = coefficients.size
    matrix = np.eye(order)
    for k in range(1, order + 1):
        for j, phi in enumerate(coefficients, start=1):
            lag = abs(k - j)
            if lag:
                matrix[k - 1, lag - 1] -= phi
    rhs = np.array([coefficients[k - 1] if k <= order else 0.0 for k in range(1, order + 1)])
    return float(np.linalg.solve(matrix, rhs)[0])


_KEPT_ROBUST = KeptByContent(TAUS_KEPT)


def autoregression(residual, max_order=MAX_AR_ORDER, penalty_per_parameter=None, min_order=0,
                   robust=False):
    """The AR noise model of ``residual`` by Yule-Walker on the autocovariance with the
    periodogram's lines cut out (so a periodic error is not taken for noise), the order
    (from ``min_order``) chosen by an information criterion: AIC (penalty 2 per parameter,
    the default for whitening) or BIC (penalty ln n). ``robust``: the autocovariance from
    the lower quartile over segments (:func:`_robust_noise_autocovariance`), so a burst is
    not taken for noise either; the robust model with the other defaults is kept by the
    residual's content (:class:`KeptByContent`, its coefficients read-only): a tracking
    diagnosis's structure searches each whiten the same residual by it."""
    if robust and (max_order, penalty_per_parameter, min_order) == (MAX_AR_ORDER, None, 0):
        return _KEPT_ROBUST.get(residual, _kept_robust_autoregression)
    return _autoregression(residual, max_order, penalty_per_parameter, min_order, robust)


def _kept_robust_autoregression(residual):
    model = _autoregression(residual, MAX_AR_ORDER, None, 0, True)
    model.coefficients.setflags(write=False)
    return model


def _autoregression(residual, max_order, penalty_per_parameter, min_order, robust):
    residual = np.asarray(residual, dtype=float) - np.mean(residual)
    max_order = min(max_order, max(residual.size // 4, 0))
    estimate = _robust_noise_autocovariance if robust else _noise_autocovariance
    autocovariance = estimate(residual, max_order)
    if autocovariance[0] <= 0.0:
        return Autoregression(np.zeros(0), 0.0, 0.0)
    penalty = 2.0 if penalty_per_parameter is None else penalty_per_parameter
    best = Autoregression(np.zeros(0), float(autocovariance[0]), float(autocovariance[0]))
    best_score = residual.size * np.log(autocovariance[0]) if min_order == 0 else np.inf
    for order in range(max(min_order, 1), max_order + 1):
        coefficients = scipy.linalg.solve_toeplitz(autocovariance[:order],
                                                   autocovariance[1:order + 1])
        variance = autocovariance[0] - coefficients @ autocovariance[1:order + 1]
        score = residual.size * np.log(max(variance, 1e-300)) + penalty * order
        if score < best_score:
            best = Autoregression(coefficients, float(max(variance, 0.0)),
                                  float(autocovariance[0]))
            best_score = score
    return best


def least_squares_autoregression(residual, max_order, min_order=1):
    """The AR model of ``residual`` by conditional least squares (x_k regressed on its p
    predecessors), the order from ``min_order`` to ``max_order`` by BIC. Less biased than
    Yule-Walker for noise correlated close to 1 over a few hundred samples (Yule-Walker's
    bias in the AR(1) coefficient is about -(1 + 3ρ)/n, which at ρ = 0.95 and n = 210
    understates the long-run variance by a third). Every order's regression is solved
    from the triangle of one QR decomposition (:func:`_lagged_triangle`)."""
    residual = np.asarray(residual, dtype=float) - np.mean(residual)
    variance = float(np.mean(residual ** 2))
    best, best_score = Autoregression(np.zeros(0), variance, variance), np.inf
    n = residual.size
    top = min(max_order, n // 4)
    if top < max(min_order, 1):
        return best
    body = _lagged_triangle(residual, top)
    for order in range(max(min_order, 1), top + 1):
        triangle = _lagged_triangle(residual[:top], order,
                                    np.column_stack((body[:, :order], body[:, -1])))
        lagged, target = triangle[:, :order], triangle[:, order]
        # the cut-off of lstsq on the n - p rows themselves: the same singular values
        coefficients = np.linalg.lstsq(lagged, target, rcond=np.finfo(float).eps * (n - order))[0]
        innovation = float(np.sum((target - lagged @ coefficients) ** 2)) / (n - order)
        score = (n - order) * np.log(max(innovation, 1e-300)) + np.log(n) * order
        if score < best_score and np.all(np.abs(np.roots(np.r_[1.0, -coefficients])) < 1.0):
            spread = innovation * np.sum(np.linalg.pinv(lagged.T @ lagged))
            best = Autoregression(coefficients, innovation, variance,
                                  float(np.sqrt(max(spread, 0.0))))
            best_score = score
    return best


LAGGED_ROWS = 1 << 16  # rows of the lagged matrix decomposed at a time (3 MB at order 5)


def _lagged_triangle(series, order, above=None):
    """R (``order`` + 1 square) of the QR decomposition of the rows [x_{k-1} .. x_{k-p},
    x_k] of ``series``, k from p = ``order`` to its end, under the rows ``above`` (of the
    same columns): the regression of x_k on its p predecessors, its Gram matrix RᵀR.
    Householder QR over ``LAGGED_ROWS`` rows at a time, each block stacked under the
    triangle so far (as stable as one decomposition of the whole, in the memory of one
    block)."""
    triangle = np.zeros((0, order + 1)) if above is None else above
    windows = (sliding_window_view(series, order + 1)[:, ::-1] if series.size > order
               else np.zeros((0, order + 1)))  # x_k, x_{k-1}, .., x_{k-p}
    for first in range(0, max(len(windows), 1), LAGGED_ROWS):
        rows = np.roll(windows[first:first + LAGGED_ROWS], -1, axis=1)
        triangle = np.linalg.qr(np.vstack((triangle, rows)), mode="r")
    return triangle


def ljung_box_p_value(residual, lags, groups=None):
    """p-value of the Ljung-Box test that ``residual`` is white over ``lags`` lags:
    Q = n(n+2) Σ ρ(k)²/(n-k) against χ² with ``lags`` degrees of freedom (Ljung & Box 1978,
    Biometrika 65:297). With ``groups`` (a group index per sample) only pairs of samples in
    different groups count, each lag's term weighted by its n_k pairs (the Box-Pierce form):
    deviations from their group means are correlated within a group by construction, not
    across groups. The sums run over ``LAGGED_ROWS`` samples at a time (no sample-sized
    temporary: at 10^7 samples the products and their selection held 240 MB)."""
    residual = np.asarray(residual, dtype=float)
    n = residual.size
    mean = 0.0 if groups is not None else float(np.mean(residual))
    spread = _block_sum(residual, mean, 0)[0] / n if n else 0.0
    if n <= lags + 1 or spread <= 0.0:
        return 1.0
    statistic = 0.0
    for lag in range(1, lags + 1):
        total, count = _block_sum(residual, mean, lag, groups)
        if count < 2:
            continue
        rho = total / count / spread
        statistic += (n * (n + 2) / (n - lag) if groups is None else count) * rho ** 2
    return float(chi2_sf(statistic, lags))


def block_variance(values):
    """``np.var(values)`` summed ``LAGGED_ROWS`` samples at a time (no sample-sized
    temporary; the same up to the order of the sums)."""
    return _block_sum(values, float(np.mean(values)), 0)[0] / values.size


def _block_sum(residual, mean, lag, groups=None):
    """(Σ (r_k - mean)(r_{k-lag} - mean), the count of pairs) over k >= ``lag``, only pairs
    in different ``groups`` where given; ``LAGGED_ROWS`` products at a time."""
    total, count = 0.0, 0
    for first in range(lag, residual.size, LAGGED_ROWS):
        stop = min(first + LAGGED_ROWS, residual.size)
        products = (residual[first:stop] - mean) * (residual[first - lag:stop - lag] - mean)
        if groups is not None and lag:
            products = products[groups[first:stop] != groups[first - lag:stop - lag]]
        total += float(np.sum(products))
        count += products.size
    return total, count


def whitened(residual, robust=False):
    """The residual through the Yule-Walker autoregressive filter of its noise (order by
    AIC), lines cut out before the fit; ``robust``: its spectrum estimated robustly (see
    :func:`autoregression`). The first samples, as many as the filter's order, are dropped."""
    return autoregression(residual, robust=robust).whiten(residual)


# x[i] from x[i-2], x[i-1], x[i+1], x[i+2] by the cubic through them
CUBIC_WEIGHTS = np.array([-1.0, 4.0, 0.0, 4.0, -1.0]) / 6.0


def _cubic_departure(values):
    """Each sample less the cubic through its two neighbours on each side; 0 at the two
    samples at each end (they have no two neighbours on one side)."""
    departure = np.zeros_like(values)
    departure[2:-2] = values[2:-2] - np.correlate(values, CUBIC_WEIGHTS, mode="valid")
    return departure


def spikes(residual, alpha, floor=0.0):
    """Indices (0-based, sorted) of single-sample spikes in ``residual`` (a series in time);
    none departs by ``floor`` or less (rounding).

    The sample departing most from the cubic through its neighbours is a spike when the
    departure passes the limit and, once it is replaced by that cubic, none of its four
    neighbours still does (a kink or a fast change of the signal moves several samples);
    repeated until the largest departure left is within the limit.
    """
    values = np.array(residual, dtype=float)
    n = values.size
    found = []
    if n < 8:
        return np.zeros(0, dtype=int)
    limit = norm_isf(alpha / (2 * n))
    judged = np.zeros(n, dtype=bool)
    for _ in range(n // 10):
        departure = _cubic_departure(values)
        scale = 1.4826 * median(np.abs(departure[~judged]))
        candidates = np.where(judged, 0.0, np.abs(departure))
        index = int(np.argmax(candidates))
        if not scale > 0.0 or candidates[index] <= max(limit * scale, floor):
            break
        judged[index] = True
        trial = values.copy()
        trial[index] -= departure[index]
        around = _cubic_departure(trial)[max(index - 2, 0):index + 3]
        if np.sum(np.abs(around) > limit * scale) == 0:
            values = trial
            found.append(index)
    return np.array(sorted(found), dtype=int)


def periodogram(residual, sample_s):
    """(frequency_hz, power) of the mean-removed residual at the Fourier frequencies, DC out."""
    centred = np.asarray(residual, dtype=float) - np.mean(residual)
    power = np.abs(np.fft.rfft(centred)) ** 2 / centred.size
    return np.fft.rfftfreq(centred.size, sample_s)[1:], power[1:]


def peak_p_value(residual, sample_s, min_cycles=1, robust=False):
    """(frequency_hz, family-wise p-value, ratio) of the strongest line in the whitened
    residual's periodogram, over the mean level of the other ordinates; only frequencies
    of at least ``min_cycles`` cycles over the record are searched (and counted);
    ``robust``: whitened by the robust noise model (:func:`whitened`)."""
    frequency_hz, power = periodogram(whitened(residual, robust), sample_s)
    searched = np.arange(power.size) >= min_cycles - 1
    index = int(np.flatnonzero(searched)[np.argmax(power[searched])])
    level = (np.sum(power) - power[index]) / max(power.size - 1, 1)
    ratio = power[index] / max(level, 1e-300)
    single = np.exp(-ratio)
    p_value = (float(-np.expm1(searched.sum() * np.log1p(-single))) if single < 1 else 1.0)
    return float(frequency_hz[index]), p_value, float(ratio)


@dataclass(frozen=True)
class TimeFrequencyPeak:
    """The strongest ordinate of the short-time periodogram: its frequency (Hz), the window
    (first and last sample index of the residual) and length (samples), its ratio to the
    noise level, the ordinates tried and the family-wise p-value."""

    frequency_hz: float
    first: int
    last: int
    window: int
    ratio: float
    trials: int
    p_value: float


def window_lengths(n):
    """Window lengths (samples) of the short-time periodogram of ``n`` whitened samples:
    ``MIN_WINDOW`` doubling up to a quarter of the record."""
    lengths = []
    length = MIN_WINDOW
    while 4 * length <= n:
        lengths.append(length)
        length *= 2
    return lengths


MEDIAN_STRIDE = 64  # every 64th value brackets a large array's median (:func:`median`)


def median(values):
    """``np.median`` of all ``values``, the same value to the bit, in about 40 % of its time
    on a large array: its partition of n values is what costs (5.5 ms at 500,000). The
    values within a bracket of the middle of every ``MEDIAN_STRIDE``-th value sorted (eight
    standard errors of that middle's rank either side) hold the two middle order
    statistics when as many lie below the bracket's lower end as their ranks allow; only
    they are partitioned. Where the bracket misses them, or a value is NaN (not below, in
    nor above it), np.median partitions all (the short-time periodogram's eleven levels
    and the robust scales of a 500 s servo trace: 0.14 -> 0.06 s)."""
    values = np.ravel(values)
    sample = np.sort(values[::MEDIAN_STRIDE])
    if sample.size < MEDIAN_STRIDE:
        return np.median(values)
    middle, half = sample.size // 2, 4 * int(np.sqrt(sample.size))
    low, high = sample[max(middle - half, 0)], sample[min(middle + half, sample.size - 1)]
    below = np.count_nonzero(values < low)
    inside = values[(values >= low) & (values <= high)]
    ranks = [(values.size - 1) // 2 - below, values.size // 2 - below]
    if (ranks[0] < 0 or ranks[1] >= inside.size
            or below + inside.size + np.count_nonzero(values > high) != values.size):
        return np.median(values)
    return np.median(np.partition(inside, ranks)[ranks[0]:ranks[1] + 1])


def clipped(values):
    """``values`` clipped at ``CLIP_SIGMA`` robust standard deviations (median absolute
    deviation) about their median."""
    centre = median(values)
    scale = 1.4826 * median(np.abs(values - centre))
    if not scale > 0.0:
        return values - centre
    return np.clip(values - centre, -CLIP_SIGMA * scale, CLIP_SIGMA * scale)


def short_time_peak(residual, sample_s):
    """The strongest sinusoid in any window of the whitened, clipped residual
    (:class:`TimeFrequencyPeak`), or None when the record is too short for one window."""
    white = whitened(residual, robust=True)
    offset = len(residual) - white.size
    white = clipped(white)
    best, trials = None, 0
    for length in window_lengths(white.size):
        hop = length // 2
        windows = sliding_window_view(white, length)[::hop]
        power = np.abs(np.fft.rfft(windows, axis=1)[:, 1:(length + 1) // 2]) ** 2 / length
        level = median(power) / np.log(2.0)
        if not level > 0.0:
            continue
        trials += power.size
        row, column = np.unravel_index(int(np.argmax(power)), power.shape)
        ratio = float(power[row, column] / level)
        if best is None or ratio - np.log(power.size) > best[0] - np.log(best[1]):
            first = offset + row * hop
            best = (ratio, power.size, (column + 1) / (length * sample_s), first,
                    first + length - 1, length)
    if best is None:
        return None
    ratio, _, frequency_hz, first, last, length = best
    p_value = float(min(1.0, trials * np.exp(-ratio)))
    return TimeFrequencyPeak(float(frequency_hz), int(first), int(last), int(length), ratio,
                             trials, p_value)


def _gated_fit(values, cosine, sine, edges):
    """For each (first, stop) in ``edges`` (arrays of sample indices, stop exclusive): the
    sum of squares a sinusoid (the ``cosine``, ``sine`` columns) explains in ``values`` over
    those samples, by prefix sums."""
    def prefix(column):
        return np.concatenate(([0.0], np.cumsum(column)))

    sums = [prefix(c) for c in (values * cosine, values * sine, cosine * cosine,
                                cosine * sine, sine * sine)]
    first, stop = edges
    yc, ys, cc, cs, ss = (s[stop] - s[first] for s in sums)
    determinant = cc * ss - cs * cs
    with np.errstate(divide="ignore", invalid="ignore"):
        explained = (ss * yc * yc - 2 * cs * yc * ys + cc * ys * ys) / determinant
    return np.where(determinant > 1e-12 * np.maximum(cc * ss, 1e-300), explained, 0.0)


def _best_gate(values, time_s, frequency_hz, min_samples):
    """(first, stop, explained) of the window where a sinusoid at ``frequency_hz`` explains
    most of ``values``: every pair on a coarse grid, then each edge to the sample."""
    phase = 2.0 * np.pi * frequency_hz * time_s
    cosine, sine = np.cos(phase), np.sin(phase)
    n = values.size
    grid = np.unique(np.linspace(0, n, min(GATE_GRID, n) + 1).astype(int))
    first, stop = np.meshgrid(grid, grid, indexing="ij")
    allowed = stop - first >= min_samples
    first, stop = first[allowed], stop[allowed]
    explained = _gated_fit(values, cosine, sine, (first, stop))
    best = int(np.argmax(explained))
    a, b = int(first[best]), int(stop[best])
    step = int(np.max(np.diff(grid)))
    for _ in range(2):
        starts = np.arange(max(a - step, 0), min(a + step, b - min_samples) + 1)
        a = int(starts[np.argmax(_gated_fit(values, cosine, sine,
                                            (starts, np.full(starts.size, b))))])
        stops = np.arange(max(b - step, a + min_samples), min(b + step, n) + 1)
        b = int(stops[np.argmax(_gated_fit(values, cosine, sine,
                                           (np.full(stops.size, a), stops)))])
    return a, b, float(_gated_fit(values, cosine, sine, (np.array([a]), np.array([b])))[0])


def locate_sinusoid(residual, time_s, frequency_hz, bin_hz):
    """(first, stop, frequency_hz, localised) of a sinusoid near ``frequency_hz`` in the
    whitened residual: the window (sample indices of ``residual``, stop exclusive) and
    frequency (refined within ``bin_hz``) where a gated sinusoid fits it best by least
    squares, alternately twice. ``localised`` is whether the gate describes it better than
    a sinusoid over the whole record by the Bayesian information criterion (two more
    parameters: the edges), on the whitened samples.
    """
    white = whitened(residual, robust=True)
    offset = len(residual) - white.size
    white = clipped(white)
    times = np.asarray(time_s, dtype=float)[offset:]
    step_s = float(np.median(np.diff(times)))
    a, b = 0, white.size
    for _ in range(2):
        min_samples = max(8, int(np.ceil(2.0 / (frequency_hz * step_s))))
        a, b, _ = _best_gate(white, times, frequency_hz, min(min_samples, white.size))
        gate = slice(a, b)
        refined = scipy.optimize.minimize_scalar(
            lambda f: -_gated_fit(white[gate], *_phases(times[gate], f),
                                  (np.array([0]), np.array([b - a])))[0],
            bounds=(max(frequency_hz - bin_hz, 0.5 * bin_hz), frequency_hz + bin_hz),
            method="bounded", options={"xatol": 1e-4 * bin_hz})
        frequency_hz = float(refined.x)
    gated = _gated_fit(white, *_phases(times, frequency_hz), (np.array([a]), np.array([b])))[0]
    whole = _gated_fit(white, *_phases(times, frequency_hz),
                       (np.array([0]), np.array([white.size])))[0]
    total = float(white @ white)
    n = white.size
    localised = bool(n * np.log(max(total - whole, 1e-300) / max(total - gated, 1e-300))
                     > 2.0 * np.log(n))
    return offset + a, offset + b, frequency_hz, localised


def _phases(time_s, frequency_hz):
    phase = 2.0 * np.pi * frequency_hz * time_s
    return np.cos(phase), np.sin(phase)


def noise_floor_um(residual_um):
    """The measurement's noise floor (µm): what a model of the motion cannot carry, from the
    residual's sample-to-sample changes (median absolute successive difference, scaled to a
    standard deviation for white noise). A slow model error barely moves it, so a residual
    far above it is structure, not noise; serially correlated noise makes it a lower bound."""
    steps = np.diff(np.asarray(residual_um, dtype=float))
    if steps.size == 0:
        return 0.0
    return float(1.4826 * median(np.abs(steps - median(steps))) / np.sqrt(2.0))
