"""Least squares through the unit-scaled Gram matrix: the numbers of the scaled copy of
the columns it replaced (1e-12 relative), and NumPy's QR-based solve (to the normal
equations' squared condition)."""
import numpy as np
import pytest

from feedaxis.stats.linear import normal_solve, unit_gram


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
