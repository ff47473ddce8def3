"""stats/coloured.py on series of known structure: the coefficient and innovation variance
of a seeded AR(1) process, its integrated autocorrelation time (1 + ρ)/(1 - ρ), and the
Ljung-Box test's false-alarm rate on white noise and its blocked sums against whole-array
ones; the median from a bracket against NumPy's."""
import numpy as np
import pytest
import scipy

from feedaxis.stats.coloured import (LAGGED_ROWS, SOKAL_WINDOW, autocorrelation_time,
                                     block_variance, least_squares_autoregression,
                                     ljung_box_p_value, median)


def ar1(rho, n, seed):
    """x_k = ρ x_{k-1} + w_k, w ~ N(0, 1), started from its stationary distribution."""
    w = np.random.default_rng(seed).normal(size=n)
    x = np.empty(n)
    x[0] = w[0] / np.sqrt(1.0 - rho ** 2)
    for k in range(1, n):
        x[k] = rho * x[k - 1] + w[k]
    return x


@pytest.mark.parametrize("rho", [0.5, 0.9])
def test_least_squares_recovers_the_ar1_coefficient_and_innovation_variance(rho):
    x = ar1(rho, 20_000, seed=1)
    model = least_squares_autoregression(x, max_order=3)
    standard_error = np.sqrt((1.0 - rho ** 2) / x.size)
    assert model.coefficients[0] == pytest.approx(rho, abs=4 * standard_error)
    assert model.innovation_variance == pytest.approx(1.0, rel=0.05)


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.8])
def test_the_autocorrelation_time_of_ar1_is_one_plus_rho_over_one_minus_rho(rho):
    tau = np.mean([autocorrelation_time(ar1(rho, 20_000, seed)) for seed in range(4)])
    assert tau == pytest.approx((1.0 + rho) / (1.0 - rho), rel=0.1)


def _tau_over_every_lag(residual):
    """Sokal's τ from the autocovariance at every lag (zero-padded to 2n − 1, the path
    before the window was first sought over the lags up to n / 8)."""
    from feedaxis.stats.coloured import _autocovariance

    autocovariance = _autocovariance(residual)
    if autocovariance[0] <= 0.0:
        return 1.0
    tau = 1.0 + 2.0 * np.cumsum(autocovariance[1:] / autocovariance[0])
    stop = np.flatnonzero(np.arange(1, autocovariance.size) >= SOKAL_WINDOW * tau)
    return float(max(tau[stop[0]] if stop.size else tau[-1], 1.0))


@pytest.mark.parametrize("seed", range(3))
def test_the_autocorrelation_time_from_the_first_lags_is_every_lag_s(seed):
    """White, AR(1) and smoothed series whose window closes within n / 8 lags, a random
    walk's and a slow sinusoid's that do not (τ from every lag then), and short series:
    τ as from the autocovariance at every lag within 1e-12 (the transforms' lengths
    differ, so their rounding does: about 1e-16 of each ρ)."""
    from feedaxis.stats.coloured import SOKAL_FIRST_SHARE, _autocorrelation_time

    rng = np.random.default_rng(seed)
    n = 40_000
    series = [rng.normal(size=n), ar1(0.5 + 0.2 * seed, n, seed),
              np.convolve(rng.normal(size=n), np.ones(50), "same"),
              rng.normal(size=n).cumsum(), np.sin(np.arange(n) * 3e-4) + rng.normal(size=n),
              rng.normal(size=7), np.ones(5)]
    closes = []
    for values in series:
        tau = _autocorrelation_time(values)
        assert tau == pytest.approx(_tau_over_every_lag(values), rel=1e-12)
        closes.append(SOKAL_WINDOW * tau <= values.size // SOKAL_FIRST_SHARE)
    assert closes[:3] == [True] * 3 and closes[3:5] == [False] * 2


def test_ljung_box_on_white_noise_alarms_at_its_level():
    """400 white series: the share of p < 0.05 lies in the 99.9 % binomial band of 0.05."""
    rng = np.random.default_rng(7)
    p_values = np.array([ljung_box_p_value(rng.normal(size=300), lags=10)
                         for _ in range(400)])
    band = 3.29 * np.sqrt(0.05 * 0.95 / p_values.size)
    assert abs(np.mean(p_values < 0.05) - 0.05) <= band


def _ljung_box_whole(residual, lags, groups=None):
    """The Ljung-Box p-value over whole sample-sized arrays (the form before the sums ran
    in blocks), the reference the blocked one must match."""
    residual = residual - (0.0 if groups is not None else np.mean(residual))
    n, variance = residual.size, float(np.mean(residual ** 2))
    statistic = 0.0
    for lag in range(1, lags + 1):
        pairs = np.ones(n - lag, dtype=bool) if groups is None else groups[lag:] != groups[:-lag]
        rho = float(np.mean((residual[lag:] * residual[:-lag])[pairs])) / variance
        statistic += (n * (n + 2) / (n - lag) if groups is None else int(pairs.sum())) * rho ** 2
    return float(scipy.stats.chi2.sf(statistic, lags))


@pytest.mark.parametrize("grouped", [False, True])
def test_ljung_box_in_blocks_matches_the_whole_array_sums(grouped):
    """Over several blocks of samples, weakly correlated (p between 0 and 1), with and
    without groups (the series then off zero, as the mean is taken out only without them):
    the p-value of the whole-array sums within 1e-12."""
    x = ar1(0.004, 3 * LAGGED_ROWS + 123, 5) + (0.0 if grouped else 0.5)
    groups = np.repeat(np.arange(x.size // 3 + 1), 3)[:x.size] if grouped else None
    expected = _ljung_box_whole(x, 5, groups)
    assert 1e-6 < expected < 0.999
    assert ljung_box_p_value(x, 5, groups) == pytest.approx(expected, rel=1e-12)


def test_the_variance_in_blocks_is_numpys():
    x = ar1(0.3, 2 * LAGGED_ROWS + 99, 8) * 1e-3 + 7.0
    assert block_variance(x) == pytest.approx(float(np.var(x)), rel=1e-12)


def _median_cases(rng):
    """Arrays whose median the bracket finds (odd and even sizes, skewed, tied, a
    constant, 2-D) and ones it misses (a pattern repeating every 64 values, whose sample is
    one value, and a NaN): (values, whether the bracket holds the middle)."""
    periodic = np.tile(np.arange(64.0), 4000)
    with_nan = rng.normal(size=100_001)
    with_nan[777] = np.nan
    return [(rng.normal(size=100_001), True), (rng.exponential(size=250_000), True),
            (np.round(rng.normal(size=480_000), 1), True), (np.full(70_000, 2.5), True),
            (rng.normal(size=(3000, 31)) ** 2, True), (rng.normal(size=4095), True),
            (rng.normal(size=300), False), (periodic, False), (with_nan, False)]


def test_the_median_from_a_bracket_is_numpys_to_the_bit(monkeypatch):
    """Each array's median equals np.median's to the bit; where the bracket holds the two
    middle values only they reach np.median (the partition of all is saved), elsewhere
    np.median takes all the values."""
    rng = np.random.default_rng(11)
    whole = np.median
    sizes = []
    monkeypatch.setattr(np, "median", lambda values: sizes.append(np.size(values))
                        or whole(values))
    for values, bracketed in _median_cases(rng):
        expected = whole(values)
        sizes[:] = []
        found = median(values)
        assert np.array_equal(found, expected, equal_nan=True) and type(found) is type(expected)
        assert (max(sizes) <= 2) == bracketed
