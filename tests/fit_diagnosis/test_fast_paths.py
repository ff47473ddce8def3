"""Fast paths give the numbers of the straightforward ones (seeded cases, 1e-12 relative)."""
import numpy as np
import pytest

from feedaxis.stats.coloured import Autoregression
from feedaxis.stats.noise import PureError, Serial, spectral_gram


def plain_gram(jacobian, spectrum):
    """J'ΣJ through the FFT of every column at once (the formula, unrearranged)."""
    n_fft = 1 << int(np.ceil(np.log2(2 * jacobian.shape[0])))
    transform = np.fft.rfft(jacobian, n_fft, axis=0)
    weights = spectrum(n_fft) / n_fft
    weights[1:-1] *= 2.0
    return np.real((transform.conj() * weights[:, None]).T @ transform)


def circulant_gram(jacobian, spectrum):
    """J'ΣJ with Σ formed: the circulant autocovariance of the spectrum, lags |i - j|."""
    n = jacobian.shape[0]
    n_fft = 1 << int(np.ceil(np.log2(2 * n)))
    autocovariance = np.fft.irfft(spectrum(n_fft), n_fft)
    lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    return jacobian.T @ autocovariance[lags] @ jacobian


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_spectral_gram_is_the_plain_formula(seed):
    rng = np.random.default_rng(seed)
    jacobian = rng.normal(size=(1500 + 37 * seed, 4))
    noise = Autoregression(np.array([0.6, -0.2, 0.1])[:seed], 0.3, 0.5)
    fast = spectral_gram(jacobian.T, noise.spectrum)
    np.testing.assert_allclose(fast, plain_gram(jacobian, noise.spectrum), rtol=1e-12,
                               atol=1e-12 * np.abs(fast).max())
    np.testing.assert_allclose(fast, circulant_gram(jacobian, noise.spectrum), rtol=1e-10,
                               atol=1e-10 * np.abs(fast).max())


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_spectral_gram_in_blocks_is_the_gram_of_pairs(seed, monkeypatch):
    """Blocks of 1 (two transforms held at a time: each row's against every later one's),
    2, 3 and all 5 rows give the same matrix, to the last bit (the same products of the
    same transforms), and the plain formula's."""
    from feedaxis.stats import noise as noise_module

    rng = np.random.default_rng(seed)
    jacobian = rng.normal(size=(900 + 41 * seed, 5)) * np.array([1e-3, 1.0, 1e3, 7.0, 0.1])
    noise = Autoregression(np.array([0.9, -0.3, 0.05])[:seed], 0.2, 0.7)
    n_fft = 1 << int(np.ceil(np.log2(2 * jacobian.shape[0])))
    grams = []
    for held in (1, 2, 3, 5):
        monkeypatch.setattr(noise_module, "SPECTRA_BYTES", 16 * (n_fft // 2 + 1) * (held + 1))
        grams.append(spectral_gram(jacobian.T, noise.spectrum))
    expected = plain_gram(jacobian, noise.spectrum)
    for gram in grams:
        np.testing.assert_array_equal(gram, grams[0])
        np.testing.assert_array_equal(gram, gram.T)
    np.testing.assert_allclose(grams[0], expected, rtol=1e-12,
                               atol=1e-12 * np.abs(expected).max())


def test_serial_gram_in_and_out_of_order():
    """The gram in the order taken: a permuted order reorders the rows, the identity not."""
    rng = np.random.default_rng(4)
    n = 600
    groups = np.repeat(np.arange(n // 3), 3)
    jacobian = rng.normal(size=(n, 3))
    correlated = np.zeros(n)
    for i, innovation in enumerate(rng.normal(size=n)):
        correlated[i] = 0.8 * correlated[i - 1] + innovation
    order = rng.permutation(n)
    residual = np.empty(n)
    residual[order] = correlated  # AR(1) in the order taken
    serial, in_order = Serial(order, PureError(groups)), Serial(np.arange(n), PureError(groups))
    assert serial.reordered and not in_order.reordered
    noise = serial.autoregression(residual)
    assert noise.order > 0
    np.testing.assert_allclose(serial.gram(jacobian, residual, 1.0),
                               plain_gram(jacobian[order], noise.spectrum), rtol=1e-12)
    noise = in_order.autoregression(correlated)
    assert noise.order > 0
    np.testing.assert_allclose(in_order.gram(jacobian, correlated, 1.0),
                               plain_gram(jacobian, noise.spectrum), rtol=1e-12)


def test_autoregression_kept_by_content():
    """A residual seen again (equal content, another array) gets the model fitted to it;
    another residual its own."""
    rng = np.random.default_rng(5)
    n = 900
    correlated = np.zeros(n)
    for i, innovation in enumerate(rng.normal(size=n)):
        correlated[i] = 0.7 * correlated[i - 1] + innovation
    serial = Serial(np.arange(n), PureError(np.repeat(np.arange(n // 3), 3)))
    first = serial.autoregression(correlated)
    assert serial.autoregression(correlated.copy()) is first
    fresh = serial._autoregression(correlated)
    np.testing.assert_array_equal(first.coefficients, fresh.coefficients)
    other = correlated[::-1].copy()
    assert serial.autoregression(other) is not first
    np.testing.assert_array_equal(serial.autoregression(other).coefficients,
                                  serial._autoregression(other).coefficients)


@pytest.mark.parametrize("key_limit", [None, 64])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_row_groups_are_numpys_unique_rows(seed, key_limit, monkeypatch):
    """The groups of distinct rows through integer keys: NumPy's structured unique rows,
    also where the key is ranked before a digit would take it past its limit."""
    from feedaxis import iso230
    from feedaxis.iso230 import row_groups

    if key_limit:
        monkeypatch.setattr(iso230, "KEY_LIMIT", key_limit)
    rng = np.random.default_rng(seed)
    n = 5000
    columns = (np.round(rng.uniform(-50.0, 50.0, n), 1), rng.choice([-1.0, 1.0], n),
               rng.integers(1, 4 + seed, n).astype(float))
    for count in (1, 2, 3):
        expected = np.unique(np.column_stack(columns[:count]), axis=0, return_inverse=True)[1]
        np.testing.assert_array_equal(row_groups(*columns[:count]), expected.ravel())


@pytest.mark.parametrize("size", [1, 2, 7, 1000, 4801, 24799])
def test_the_autocovariance_by_fft_is_the_lagged_sum(size):
    """Zero-padded to a fast length (24,799 makes 2n a large prime's double): the biased
    autocovariance (1/n) Σ x_t x_{t+k} of the mean-removed samples, at every lag."""
    from feedaxis.stats.coloured import _autocovariance

    values = np.random.default_rng(size).normal(size=size).cumsum()
    centred = values - values.mean()
    lags = np.arange(size) if size <= 1000 else np.array([0, 1, 2, 17, size // 2, size - 1])
    direct = np.array([centred[:size - k] @ centred[k:] for k in lags]) / size
    fast = _autocovariance(values)[lags]
    np.testing.assert_allclose(fast, direct, rtol=1e-12, atol=1e-12 * abs(direct[0]))


def scipy_robust_drift(layout, residual_um):
    """The drift of :func:`feedaxis.stats.judge._robust_drift` by SciPy's trust region with
    the soft-L1 loss (the path before Newton's method over blocks of rows)."""
    from scipy.optimize import least_squares

    from feedaxis.stats.judge import MAD_TO_SIGMA, drift_basis

    within = drift_basis(layout.clock)
    for column in within.T:
        column -= layout.group_means(column)
    target = residual_um - layout.group_means(residual_um)
    scale = MAD_TO_SIGMA * np.median(np.abs(target))
    solution = least_squares(lambda c: within @ c - target, np.zeros(2), loss="soft_l1",
                             f_scale=scale)
    return within @ solution.x, solution.x, (within, target, scale)


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_the_robust_drift_is_scipys_soft_l1_optimum(seed, monkeypatch):
    """Newton's method over blocks of rows lands on SciPy's soft-L1 optimum (within SciPy's
    own tolerance: its gradient there is 1e-8 of the data's, Newton's at rounding), and the
    outliers flagged are the same rows."""
    import synthetic as syn
    from feedaxis.measurement.positioning import Positioning
    from feedaxis.stats import judge

    rng = np.random.default_rng(seed)
    case, spikes = syn.iso_trial(rng, drift_um_per_run=0.4, outliers=3)
    measurement = Positioning(case)
    layout, residual = measurement.layout, measurement.measured_um - measurement.measured_um.mean()
    assert layout.clock_varies_within_groups
    old_drift, old_coefficients, (within, target, scale) = scipy_robust_drift(layout, residual)
    new = judge.soft_l1_line(within, target, scale, block=7)
    np.testing.assert_allclose(new, old_coefficients, rtol=1e-6)
    u = (within @ new - target) / scale
    gradient = within.T @ (2 * scale * u / np.sqrt(1 + u * u))
    assert np.abs(gradient).max() <= 1e-12 * np.abs(within.T @ target).max()
    rows = judge.outlier_rows(layout, measurement.position_mm, residual)
    assert set(spikes) <= set(rows)
    monkeypatch.setattr(judge, "_robust_drift", lambda lay, res: scipy_robust_drift(lay, res)[0])
    np.testing.assert_array_equal(rows, judge.outlier_rows(layout, measurement.position_mm,
                                                           residual))


@pytest.mark.parametrize("seed", [1, 2])
def test_unit_column_svd_is_the_svd_of_the_unit_columns(seed):
    """The norms from the Gram matrix's diagonal are the columns' norms; its eigenvectors
    the right singular vectors of the unit-column Jacobian."""
    from feedaxis.fit import _unit_column_svd

    rng = np.random.default_rng(seed)
    jacobian = rng.normal(size=(5000, 4)) * np.array([1e-3, 1.0, 1e3, 7.0])
    scale, singular, vt, strong = _unit_column_svd(jacobian)
    np.testing.assert_allclose(scale, np.linalg.norm(jacobian, axis=0), rtol=1e-12)
    _, expected, expected_vt = np.linalg.svd(jacobian / np.linalg.norm(jacobian, axis=0),
                                             full_matrices=False)
    np.testing.assert_allclose(singular, expected, rtol=1e-12)
    np.testing.assert_allclose(np.abs(vt), np.abs(expected_vt), atol=1e-10)
    assert strong.all()


def _split_case(seed):
    """A seeded bidirectional case with ambient air and three positioning effects in it."""
    import synthetic as syn

    rng = np.random.default_rng(seed)
    run = np.repeat(np.arange(1, 4), 40)
    target_mm = np.tile(np.concatenate((np.linspace(0, 480, 20), np.linspace(480, 0, 20))), 3)
    target_mm = target_mm + rng.uniform(-20, 20, target_mm.size)
    direction = np.tile(np.repeat([1.0, -1.0], 20), 3)
    ambient_C = 20 + rng.uniform(-1, 1, target_mm.size)
    error_um = rng.normal(0.0, 0.3, target_mm.size) + 0.2 * direction
    return syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=error_um,
                              direction=direction, run=run, ambient_C=ambient_C)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_split_is_every_effect_evaluated_alone(seed):
    """The fit's split (each effect's columns copied into one array as it is split, none
    kept) against each effect's own prediction, evaluated alone at random values: base +
    columns @ linear is the model's prediction, and each call gives arrays of its own."""
    from feedaxis.effects import CATALOG, BasisEffect, Model
    from feedaxis.measurement import measurement_of

    rng = np.random.default_rng(seed)
    case = _split_case(seed)
    measurement = measurement_of(case, "positioning")
    basis = np.column_stack((measurement.position_mm / 500.0, measurement.direction))
    effects = [CATALOG[name] for name in ("lead_error", "backlash", "assembly_eccentricity",
                                          "ambient_expansion")] + [BasisEffect("drift", basis)]
    values = {e.name: {p.name: float(rng.uniform(-2, 2)) for p in e.parameters}
              for e in effects}
    model = Model(effects, values)
    separate = measurement.separable(model)
    base_um, columns_um = separate(values)
    linear = np.array([values[e.name][p] for e in effects for p in e.linear])
    alone_um = sum(e.prepare(case)(values[e.name]) for e in effects)
    assert np.allclose(base_um + columns_um @ linear, alone_um, rtol=1e-12,
                       atol=1e-12 * np.abs(alone_um).max())
    columns_um[:] = np.nan
    again_um, again_columns_um = separate(values)
    assert np.allclose(again_um + again_columns_um @ linear, alone_um, rtol=1e-12,
                       atol=1e-12 * np.abs(alone_um).max())


@pytest.mark.parametrize("seed", [1, 2])
def test_the_split_kept_across_linear_values_is_a_fresh_one(seed):
    """The residual at a vector whose nonlinear parameters match the split kept (only the
    linear ones moved) is the residual of a problem that never split before."""
    from feedaxis.effects import CATALOG, Model
    from feedaxis.fit import ParameterLayout, Problem
    from feedaxis.measurement import measurement_of

    case = _split_case(seed)
    measurement = measurement_of(case, "positioning")
    effects = [CATALOG["lead_error"], CATALOG["ambient_expansion"]]
    model = Model(effects, {"lead_error": {"offset_um": 0.1, "slope_um_per_mm": 0.01},
                            "ambient_expansion": {"reference_offset_mm": 3.0}})
    layout = ParameterLayout(model, case.axis)
    start = layout.start()
    moved = start.copy()
    moved[layout.linear_index] += np.random.default_rng(seed).uniform(-1, 1,
                                                                      layout.linear_index.size)
    kept = Problem(model, [measurement]).residual(layout)
    kept(start)
    fresh = Problem(model, [measurement]).residual(layout)(moved)
    assert np.array_equal(kept(moved), fresh)


def test_clusters_kept_for_read_only_targets_are_the_computed_ones():
    """The clusters kept for a read-only target array (as the case reader gives it) are
    those computed anew from a writeable copy, read-only themselves, and forgotten with
    the array."""
    import gc

    from feedaxis import iso230

    rng = np.random.default_rng(5)
    target_mm = np.repeat(np.arange(40) * 12.5, 6) + rng.uniform(-1e-6, 1e-6, 240)
    rng.shuffle(target_mm)
    computed = iso230.target_clusters(target_mm.copy())
    target_mm.flags.writeable = False
    kept = iso230.target_clusters(target_mm)
    assert iso230.target_clusters(target_mm) is kept
    for ours, theirs in zip(kept, computed):
        assert np.array_equal(ours, theirs) and not ours.flags.writeable
    key = id(target_mm)
    del target_mm
    gc.collect()
    assert key not in iso230._KEPT_CLUSTERS


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_run_clock_is_each_runs_places_in_row_order(seed):
    """The clock of run + place in the run, every run at once, against each run's samples
    taken in turn (the runs shuffled, uneven, numbered with gaps)."""
    from types import SimpleNamespace

    from feedaxis.stats.judge import clock_of

    rng = np.random.default_rng(seed)
    run = rng.choice([1, 2, 5, 9, 40], size=500 + 17 * seed)
    run_float = run.astype(float)
    expected = np.empty(run.size)
    for value in np.unique(run_float):
        members = np.flatnonzero(run_float == value)
        expected[members] = value + np.arange(members.size) / members.size
    clock, unit = clock_of(SimpleNamespace(time_s=None, run=run))
    assert unit == "run" and np.array_equal(clock, expected)


def lstsq_autoregression(residual, max_order):
    """Conditional least squares order by order: np.linalg.lstsq on the lagged columns
    themselves (the path before one QR decomposition), the order by BIC."""
    from feedaxis.stats.coloured import Autoregression

    residual = np.asarray(residual, dtype=float) - np.mean(residual)
    variance = float(np.mean(residual ** 2))
    best, best_score, n = Autoregression(np.zeros(0), variance, variance), np.inf, residual.size
    for order in range(1, min(max_order, n // 4) + 1):
        lagged = np.column_stack([residual[order - lag:n - lag] for lag in range(1, order + 1)])
        target = residual[order:]
        coefficients = np.linalg.lstsq(lagged, target, rcond=None)[0]
        innovation = float(np.mean((target - lagged @ coefficients) ** 2))
        score = target.size * np.log(innovation) + np.log(n) * order
        if score < best_score and np.all(np.abs(np.roots(np.r_[1.0, -coefficients])) < 1.0):
            spread = innovation * np.sum(np.linalg.pinv(lagged.T @ lagged))
            best = Autoregression(coefficients, innovation, variance, float(np.sqrt(spread)))
            best_score = score
    return best


@pytest.mark.parametrize("coefficients, size", [
    ((), 5000), ((0.5,), 21), ((0.95,), 210), ((0.999,), 3000), ((0.6, -0.3), 40),
    ((1.2, -0.5, 0.1), 20_000), ((0.02,) * 5, 100_000)])
def test_autoregression_by_one_qr_is_lstsq_order_by_order(coefficients, size, monkeypatch):
    """Every order's regression from one QR decomposition (in blocks of 1,000 rows here)
    gives lstsq's coefficients, innovation variance and persistence error on the lagged
    columns themselves, the same order chosen."""
    from feedaxis.stats import coloured

    monkeypatch.setattr(coloured, "LAGGED_ROWS", 1000)
    rng = np.random.default_rng(size)
    series = np.zeros(size + 300)
    for k, innovation in enumerate(rng.normal(size=series.size)):
        series[k] = sum(c * series[k - j] for j, c in enumerate(coefficients, start=1)
                        if k >= j) + innovation
    series = series[300:]
    for max_order in (1, 2, 5):
        fast = coloured.least_squares_autoregression(series, max_order)
        plain = lstsq_autoregression(series, max_order)
        assert fast.order == plain.order
        np.testing.assert_allclose(fast.coefficients, plain.coefficients, rtol=1e-12)
        np.testing.assert_allclose([fast.innovation_variance, fast.variance,
                                    fast.persistence_error],
                                   [plain.innovation_variance, plain.variance,
                                    plain.persistence_error], rtol=1e-12)


@pytest.mark.parametrize("distinct", [3, 5000, 70_000])
def test_ranks_are_numpys_unique_inverse_and_distinct_rows_its_count(distinct):
    """A column of few values (searched) and of many (sorted by index), beyond the first
    samples' hint too: NumPy's unique values and inverse; the rows' count that of
    row_groups and of NumPy's unique rows (none and one row too)."""
    from feedaxis.iso230 import FEW_VALUES, distinct_rows, ranks, row_groups

    rng = np.random.default_rng(distinct)
    column = np.concatenate((np.zeros(FEW_VALUES), rng.integers(0, distinct, 3 * FEW_VALUES)
                             * 0.25))
    values, index = ranks(column)
    expected = np.unique(column, return_inverse=True)
    np.testing.assert_array_equal(values, expected[0])
    np.testing.assert_array_equal(index, expected[1].ravel())
    other = rng.choice([-1.0, 1.0], column.size)
    rows = np.unique(np.column_stack((column, other)), axis=0).shape[0]
    assert distinct_rows(column, other) == row_groups(column, other).max() + 1 == rows
    assert distinct_rows(column[:1], other[:1]) == 1
    assert distinct_rows(column[:0], other[:0]) == 0


@pytest.mark.parametrize("dtype", [np.int64, np.int32, np.uint8])
def test_dense_keys_rank_as_numpys_unique(dtype):
    """Whole numbers from 0 to fewer than their count (a dense key, ranked by the keys
    present) and others (negative, too large: sorted): NumPy's unique values, their type,
    and inverse; the distinct rows counted either way."""
    from feedaxis.iso230 import distinct_rows, present_keys, ranks

    rng = np.random.default_rng(7)
    dense = rng.integers(0, 180, 200).astype(dtype)
    sparse = dense.astype(np.int64) * 1000 - 7
    assert present_keys(dense) is not None and present_keys(sparse) is None
    for column in (dense, sparse, dense[:1], rng.permutation(5000).astype(dtype)
                   if dtype != np.uint8 else dense[::-1]):
        values, index = ranks(column)
        expected = np.unique(column, return_inverse=True)
        assert values.dtype == expected[0].dtype
        np.testing.assert_array_equal(values, expected[0])
        np.testing.assert_array_equal(index, expected[1].ravel())
        assert distinct_rows(column) == expected[0].size
