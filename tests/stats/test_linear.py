"""Least squares through the unit-scaled Gram matrix: the numbers of the scaled copy of
the columns it replaced (1e-12 relative), and NumPy's QR-based solve (to the normal
equations' squared condition); the projection through a QR taken in blocks of rows against
NumPy's lstsq of the whole (1e-12), and the product subtracted in blocks against the whole
product (to the bit)."""
import numpy as np
import pytest

from feedaxis.stats.linear import (QR_ROWS, normal_solve, projection, subtract_product,
                                   unit_gram)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_normal_solve_is_the_scaled_copys_and_numpys_least_squares(seed):
    rng = np.random.default_rng(seed)
    columns = rng.normal(size=(4000, 3)) * np.array([1e-4, 1.0, 1e4])
    target = columns @ np.array([2.0, -1.0, 3e-4]) + rng.normal(size=4000)
    solved = normal_solve(columns, target)
    scale = np.linalg.norm(columns, axis=0)
    scaled = columns / scale
    copied = np.linalg.lstsq(scaled.T @ scaled, scaled.T @ target, rcond=None)[0] / scale
    np.testing.assert_allclose(solved, copied, rtol=1e-12)
    np.testing.assert_allclose(solved, np.linalg.lstsq(columns, target, rcond=None)[0],
                               rtol=1e-10)


def test_unit_gram_norms_and_a_zero_column():
    rng = np.random.default_rng(4)
    columns = np.column_stack((rng.normal(size=500), np.zeros(500), 5 * rng.normal(size=500)))
    gram, scale = unit_gram(columns)
    np.testing.assert_allclose(scale, [np.linalg.norm(columns[:, 0]), 1.0,
                                       np.linalg.norm(columns[:, 2])], rtol=1e-12)
    np.testing.assert_allclose(np.diag(gram), [1.0, 0.0, 1.0], rtol=1e-12)
    assert normal_solve(columns, columns[:, 0])[1] == 0.0  # minimum norm: the zero column


@pytest.mark.parametrize("dependent", [False, True])
def test_the_projection_in_blocks_is_numpys_least_squares_of_the_whole(dependent):
    """A cubic's columns over several blocks of rows (with a column repeated: the minimum
    norm solution's fit): the fitted values of lstsq over the whole array within 1e-12."""
    rng = np.random.default_rng(5)
    x = np.sort(rng.uniform(-1.0, 1.0, 2 * QR_ROWS + 321))
    columns = np.vander(x, 4)
    if dependent:
        columns = np.column_stack((columns, columns[:, 1]))
    target = 0.3 - x + 2 * x ** 3 + rng.normal(0.0, 0.1, x.size)
    whole = columns @ np.linalg.lstsq(columns, target, rcond=None)[0]
    np.testing.assert_allclose(projection(columns, target), whole, rtol=1e-12, atol=1e-12)


def _projection_stacked(columns, target):
    """The projection as it was first written: each block of rows stacked under the
    triangle so far (copies) and decomposed by NumPy's QR."""
    count = columns.shape[1]
    triangle = np.zeros((0, count + 1))
    for first in range(0, max(target.size, 1), QR_ROWS):
        rows = np.column_stack((columns[first:first + QR_ROWS], target[first:first + QR_ROWS]))
        triangle = np.linalg.qr(np.vstack((triangle, rows)), mode="r")
    coefficients = np.linalg.lstsq(triangle[:count, :count], triangle[:count, count],
                                   rcond=np.finfo(float).eps * max(columns.shape))[0]
    return columns @ coefficients


@pytest.mark.parametrize("rows", [QR_ROWS - 5, 3 * QR_ROWS + 17])
def test_the_projection_factored_in_place_is_the_stacked_one_and_lstsq_s_rank(rows):
    """Columns of five decades, one of them zero and one a combination of two others off by
    1e-14 of its size (numerically dependent by lstsq's cut-off, eps · rows, not exactly):
    the blocks factored in place in one buffer give the stacked copies' projection to the
    bit, and lstsq's residual within 1e-12 of its norm at lstsq's rank; the full rank's
    residual (a smaller cut-off) differs from it by far more, so the rank is what decides."""
    rng = np.random.default_rng(9)
    columns = rng.normal(size=(rows, 6)) * np.logspace(0, 5, 6)
    columns[:, 4] = 0.0
    columns[:, 5] = columns[:, 0] - 3e-5 * columns[:, 2] + 1e-14 * rng.normal(size=rows)
    target = columns @ rng.normal(size=6) + rng.normal(size=rows) + 1e3 * rng.normal() \
        * np.sign(columns[:, 5] - columns[:, 0] + 3e-5 * columns[:, 2])
    fitted = projection(columns, target)
    np.testing.assert_array_equal(fitted, _projection_stacked(columns, target))
    solved = np.linalg.lstsq(columns, target, rcond=None)
    assert solved[2] == 4
    residual = target - columns @ solved[0]
    np.testing.assert_allclose(target - fitted, residual, rtol=0,
                               atol=1e-12 * np.linalg.norm(residual))
    full = target - columns @ np.linalg.lstsq(columns, target, rcond=1e-18)[0]
    assert np.linalg.norm(full - residual) > 1e-6 * np.linalg.norm(residual)


def test_the_product_subtracted_in_blocks_is_the_whole_products_to_the_bit():
    rng = np.random.default_rng(6)
    columns, coefficients = rng.normal(size=(QR_ROWS + 77, 7)), rng.normal(size=7)
    target = rng.normal(size=QR_ROWS + 77)
    expected = target - columns @ coefficients
    np.testing.assert_array_equal(subtract_product(target, columns, coefficients), expected)
