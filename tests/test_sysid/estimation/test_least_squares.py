"""sysid.estimation.least_squares: the Gram-matrix, split, shifted CholeskyQR3 and Householder routes give lstsq's answers."""

import numpy as np
import pytest

from sysid.estimation import least_squares


def test_the_condition_test_by_bounds_decides_as_the_singular_values(rng):
    # Triangular factors of condition numbers 1 to 1e10 around the limit, singular ones and an empty one.
    for exponent in np.linspace(0, 10, 41):
        q, _ = np.linalg.qr(rng.standard_normal((12, 12)))
        r = np.linalg.qr(q * np.logspace(0, -exponent, 12))[1]
        for limit in (1e3, 1e5):
            assert least_squares._condition_below(r, limit) == (np.linalg.cond(r) < limit)
    singular = np.triu(rng.standard_normal((4, 4)))
    singular[2, 2] = 0.0
    assert not least_squares._condition_below(singular, 1e5)
    assert least_squares._condition_below(np.zeros((0, 0)), 1e5)


def test_least_squares_through_the_gram_matrix_or_householder_equal_lstsq(rng):
    # Well conditioned: the Cholesky factor of the Gram matrix (Q implicit); nearly coinciding
    # columns (condition 1e8): shifted CholeskyQR3 (Q explicit, no column dropped). Both give
    # lstsq's solution, projector and pseudo-inverse.
    well = rng.standard_normal((400, 6))
    ill = well.copy()
    ill[:, 5] = ill[:, 4] + 1e-8 * rng.standard_normal(400)
    rhs = rng.standard_normal(400)
    g = rng.standard_normal((6, 3))
    for matrix, implicit in ((well, True), (ill, False)):
        matrix = matrix / np.linalg.norm(matrix, axis=0)
        factor, x = least_squares.qr_solve(np.asfortranarray(matrix), rhs)
        assert (factor.q is None) == implicit
        assert factor.keep is None
        expected = np.linalg.lstsq(matrix, rhs, rcond=None)[0]
        np.testing.assert_allclose(matrix @ x, matrix @ expected, atol=1e-7)
        np.testing.assert_allclose(factor.q_times(factor.qt(rhs)), matrix @ expected, atol=1e-7)
    factor = least_squares.Factor(np.asfortranarray(well / np.linalg.norm(well, axis=0)))
    np.testing.assert_allclose(factor.q_times(factor.pinv_t(g)), np.linalg.pinv(well / np.linalg.norm(well, axis=0)).T @ g,
                               atol=1e-10)


@pytest.mark.parametrize("spread", [1.0, 1e-5])
def test_coinciding_columns_are_dropped_with_the_minimum_norm_solution_of_lstsq(rng, spread):
    # Coinciding poles give identical regressor columns (two real poles at z = 0), a pole pair at
    # the origin a zero column. The dependent columns are dropped and written on the kept ones;
    # the solution is lstsq's minimum-norm one, the projector and the pseudo-inverse are lstsq's.
    # spread 1e-5 leaves the kept columns ill conditioned (shifted CholeskyQR3 on them).
    base = rng.standard_normal((600, 5))
    base[:, 4] = base[:, 3] + spread * rng.standard_normal(600)
    matrix = np.column_stack([base, base[:, 1], np.zeros(600), base[:, 2] * 1.0])
    scale = np.linalg.norm(matrix, axis=0)
    matrix = np.asfortranarray(matrix / np.where(scale == 0, 1.0, scale))
    rhs, g = rng.standard_normal(600), rng.standard_normal((8, 3))
    factor, x = least_squares.qr_solve(matrix, rhs)
    dropped = set(factor.drop.tolist())
    assert len(dropped) == 3 and 6 in dropped and dropped & {1, 5} and dropped & {2, 7}
    assert (factor.q is None) == (spread == 1.0)
    cutoff = np.finfo(float).eps * 600
    expected = np.linalg.lstsq(matrix, rhs, rcond=cutoff)[0]
    assert np.linalg.norm(x - expected) <= 1e-10 * np.linalg.norm(expected)
    pinv = np.linalg.pinv(matrix, rcond=cutoff)
    np.testing.assert_allclose(factor.q_times(factor.qt(rhs)), matrix @ pinv @ rhs, atol=1e-9)
    np.testing.assert_allclose(factor.q_times(factor.pinv_t(g)), pinv.T @ g, atol=1e-7)
