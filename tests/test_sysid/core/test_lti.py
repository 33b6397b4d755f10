"""State-space realisations (sysid.core.lti): balanced realisations, truncation and state equalisation."""

import numpy as np
import pytest
import scipy.linalg

from sysid.core import lti
from sysid.core.plants import appendix_a_model
from sysid.random_plant import random_plant

Z = np.exp(1j * np.linspace(0.001, np.pi - 0.001, 400))


@pytest.mark.parametrize("seed", [0, 4, 7])
def test_balanced_realisation_of_a_random_helmet(seed):
    plant = random_plant(seed).model
    A, B, C, D = lti.balanced_realisation(plant.A, plant.B, plant.C, plant.D)
    before = lti.frequency_response(plant.A, plant.B, plant.C, plant.D, Z)
    after = lti.frequency_response(A, B, C, D, Z)
    assert np.max(np.abs(after - before)) < 1e-9 * np.max(np.abs(before))
    # Both Gramians equal one diagonal matrix, the Hankel singular values, largest first.
    wc, wo = lti.gramians(A, B, C)
    sigma = lti.hankel_singular_values(plant.A, plant.B, plant.C)
    np.testing.assert_allclose(np.diag(wc), sigma, rtol=1e-6, atol=1e-12 * sigma[0])
    np.testing.assert_allclose(wc, wo, atol=1e-9 * sigma[0])
    assert np.max(np.abs(wc - np.diag(np.diag(wc)))) < 1e-9 * sigma[0]
    # A is a contraction and |B_i|, |C_i| <= sqrt(sigma_i).
    assert np.linalg.norm(A, 2) <= 1 + 1e-9
    assert np.all(np.abs(B[:, 0]) <= np.sqrt(sigma) * (1 + 1e-6))
    assert np.all(np.abs(C[0]) <= np.sqrt(sigma) * (1 + 1e-6))


def test_nearly_coincident_poles_with_huge_residues_come_out_of_order_one():
    # 1e6 / (z - 0.9) - 1e6 / (z - 0.900001) is about -1 / (z - 0.9)^2: a modal form with a
    # unit output row holds it only with entries of 1e6 (output-error fits reach 1e12).
    A = np.diag([0.9, 0.9 + 1e-6])
    B = np.array([[1e6], [-1e6]])
    C = np.ones((1, 2))
    Ab, Bb, Cb, Db = lti.balanced_realisation(A, B, C, 0.0)
    assert max(np.abs(Ab).max(), np.abs(Bb).max(), np.abs(Cb).max()) < 10.0
    exact = -1.0 / (Z - 0.9) ** 2
    assert np.max(np.abs(lti.frequency_response(Ab, Bb, Cb, Db, Z) - exact)) < 1e-4 * np.max(np.abs(exact))


def test_equalise_states_keeps_the_blocks_and_the_response():
    A = lti.real_block_diagonal(np.array([0.9 * np.exp(0.3j), 0.9 * np.exp(-0.3j), 0.5]))
    B = np.array([[1e7], [3e6], [1e-3]])
    C = lti.block_output_row(A)
    Ae, Be, Ce, De = lti.equalise_states(A, B, C, 0.0)
    np.testing.assert_allclose(Ae, A)
    np.testing.assert_allclose(np.linalg.norm(Be[:2, 0]), np.linalg.norm(Ce[0, :2]))
    np.testing.assert_allclose(abs(Be[2, 0]), abs(Ce[0, 2]))
    np.testing.assert_allclose(lti.frequency_response(Ae, Be, Ce, De, Z), lti.frequency_response(A, B, C, 0.0, Z),
                               rtol=1e-9)


def test_unstable_system_is_only_equalised():
    A = np.array([[1.2]])
    Ab, Bb, Cb, _ = lti.balanced_realisation(A, [[100.0]], [[1.0]], 0.0)
    assert Ab[0, 0] == 1.2 and Bb[0, 0] == pytest.approx(10.0) and Cb[0, 0] == pytest.approx(10.0)


def test_a_static_gain_has_its_gain_at_every_frequency():
    # No states: the response is D alone (a model may be a pure gain, e.g. a feed-forward path's
    # model before any dynamics are added); one model and several along a leading axis.
    z = np.exp(1j * np.linspace(0.0, np.pi, 7))
    assert np.array_equal(lti.frequency_response(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[0.5]], z),
                          np.full(7, 0.5 + 0j))
    several = lti.pole_residue_response(np.zeros((3, 0)), np.zeros((3, 0)), np.array([1.0, 2.0, 3.0]), z)
    assert np.array_equal(several, np.repeat([[1.0], [2.0], [3.0]], 7, axis=1).astype(complex))


@pytest.mark.parametrize("seed", [0, 4])
@pytest.mark.parametrize("from_rest", [True, False])
def test_simulate_equals_the_state_recursion(seed, from_rest):
    # The modal simulation (a real second-order section per pole pair from rest, complex
    # first-order filters with an initial state) against x(t+1) = A x + B u, y = C x + D u.
    import scipy.signal

    plant = random_plant(seed).model
    A, B, C, D = lti.balanced_realisation(plant.A, plant.B, plant.C, plant.D)
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(3000)
    x0 = None if from_rest else rng.standard_normal(A.shape[0])
    _, expected, _ = scipy.signal.dlsim((A, B, C, D, 1.0), u, x0=x0)
    y = lti.simulate(A, B, C, D, u, x0=x0)
    np.testing.assert_allclose(y, expected[:, 0], atol=1e-9 * np.max(np.abs(expected)))


def test_simulate_with_coinciding_poles_equals_the_state_recursion():
    # Repeated poles (a Jordan block and a repeated pair) defeat the modal form; the Schur-form
    # recursion must still give x(t+1) = A x + B u, y = C x + D u.
    import scipy.signal

    rng = np.random.default_rng(3)
    pair = np.array([[0.95, 0.2], [-0.2, 0.95]])
    A = np.zeros((7, 7))
    A[:2, :2] = A[2:4, 2:4] = pair
    A[0, 2] = 1.0
    A[4:, 4:] = [[0.9, 1.0, 0.0], [0.0, 0.9, 1.0], [0.0, 0.0, 0.9]]
    Q, _ = np.linalg.qr(rng.standard_normal((7, 7)))
    A = Q @ A @ Q.T
    B, C, D = rng.standard_normal((7, 1)), rng.standard_normal((1, 7)), np.array([[0.3]])
    assert lti.modal_inverse(np.linalg.eig(A)[1])[0] is None
    u = rng.standard_normal(2000)
    _, expected, _ = scipy.signal.dlsim((A, B, C, D, 1.0), u)
    np.testing.assert_allclose(lti.simulate(A, B, C, D, u), expected[:, 0], atol=1e-9 * np.max(np.abs(expected)))


def _cluster(newton: np.ndarray):
    """Four real poles within 1e-3 of 0.9 in modal form (A = diag(p), C = [1 1 1 1]) for the Newton-form
    response sum_k newton[k] / prod_{j<=k} (z - p_j), and that response at Z: residues of 1e4 to 1e6
    that cancel."""
    p = 0.9 + np.array([0.0, 2e-4, 5e-4, 9e-4])
    r = [sum(newton[k] / np.prod([p[i] - p[j] for j in range(k + 1) if j != i]) for k in range(i, 4)) for i in range(4)]
    exact = sum(newton[k] / np.prod([Z - p[j] for j in range(k + 1)], axis=0) for k in range(4))
    return np.diag(p), np.array(r)[:, None], np.ones((1, 4)), exact


def _assert_balanced_holding(system, order: int, exact: np.ndarray) -> None:
    """``system`` (A, B, C, D) has ``order`` states, entries of order one, equal diagonal Gramians and the
    frequency response ``exact`` on Z within 1e-7 of its peak."""
    A, B, C, D = system
    assert A.shape == (order, order)
    assert max(np.abs(A).max(), np.abs(B).max(), np.abs(C).max()) < 1.0 + 1e-9
    assert np.max(np.abs(lti.frequency_response(A, B, C, D, Z) - exact)) < 1e-7 * np.max(np.abs(exact))
    wc, wo = lti.gramians(A, B, C)
    np.testing.assert_allclose(wc, wo, atol=1e-9 * wc[0, 0])
    assert np.max(np.abs(wc - np.diag(np.diag(wc)))) < 1e-9 * wc[0, 0]


def test_clustered_real_poles_with_cancelling_residues_balance_to_entries_of_order_one():
    # The Gramians of the modal form lose their small eigenvalues (the square-root method's result
    # misses the response: balanced_realisation only equalises); its chain realisation balances.
    A, B, C, exact = _cluster(np.array([1e-1, 1e-2, 1e-3, 1e-4]))
    assert np.abs(B).max() > 1e6
    assert np.abs(lti.balanced_realisation(A, B, C, 0.0)[1]).max() > 10.0
    _assert_balanced_holding(lti.balanced_truncation(A, B, C, 0.0), 4, exact)


def test_a_nearly_real_pair_among_close_real_poles_balances_to_a_real_system():
    # Random helmet 17's kind: a pair 0.9 +- 3e-5j beside real poles 2e-4 and 5e-4 away, residues of
    # 1e4-1e6 that cancel; the chain realisation is complex, its balanced form real.
    poles = np.array([0.9 + 3e-5j, 0.9 - 3e-5j, 0.9002, 0.9005])
    numerator = 1e-4 * np.poly([0.5, 0.3 + 0.2j, 0.3 - 0.2j])
    r = np.array([np.polyval(numerator, p) / np.prod(p - np.delete(poles, i)) for i, p in enumerate(poles)])
    A = lti.real_block_diagonal(poles)
    B = np.array([[2 * r[0].real], [-2 * r[0].imag], [r[2].real], [r[3].real]])
    C = lti.block_output_row(A)
    exact = np.polyval(numerator, Z) / np.prod(Z[:, None] - poles[None, :], axis=1)
    assert np.max(np.abs(lti.frequency_response(A, B, C, 0.0, Z) - exact)) < 1e-6 * np.max(np.abs(exact))
    assert np.abs(B).max() > 1e4
    Ab, Bb, Cb, Db = lti.balanced_truncation(A, B, C, 0.0)
    assert Ab.dtype == float and Ab.shape == (4, 4)
    assert max(np.abs(Ab).max(), np.abs(Bb).max(), np.abs(Cb).max()) < 1.0 + 1e-9
    assert np.max(np.abs(lti.frequency_response(Ab, Bb, Cb, Db, Z) - exact)) < 1e-6 * np.max(np.abs(exact))


def test_chained_realisation_holds_the_cluster_with_coefficients_of_the_response_size():
    A, B, C, exact = _cluster(np.array([1e-1, 1e-2, 1e-3, 1e-4]))
    Ac, Bc, Cc, Dc = lti.chained_realisation(A, B, C, 0.0)
    assert np.count_nonzero(np.diag(Ac, -1)) == 3 and max(np.abs(Bc).max(), np.abs(Cc).max()) < 10.0
    assert np.max(np.abs(lti.frequency_response(Ac, Bc, Cc, Dc, Z) - exact)) < 1e-7 * np.max(np.abs(exact))


def test_a_state_that_carries_nothing_is_left_out_by_balanced_truncation():
    # The cluster's fourth Newton coefficient zero: the order-4 modal form is an order-3 system,
    # which balanced_realisation cannot balance at order 4 (entries stay > 10) and
    # balanced_truncation holds at order 3 with entries of order one and the same response.
    A, B, C, exact = _cluster(np.array([1e-1, 1e-2, 1e-3, 0.0]))
    Ab, Bb, Cb, _ = lti.balanced_realisation(A, B, C, 0.0)
    assert max(np.abs(Bb).max(), np.abs(Cb).max()) > 10.0
    # Balanced at its own order (a discrete-time truncation alone is not).
    _assert_balanced_holding(lti.balanced_truncation(A, B, C, 0.0), 3, exact)
    # Nothing negligible: the full order, as balanced_realisation gives it (up to the states' signs).
    plant = random_plant(0).model
    full = lti.balanced_truncation(plant.A, plant.B, plant.C, plant.D)
    np.testing.assert_allclose(np.abs(full[0]), np.abs(lti.balanced_realisation(plant.A, plant.B, plant.C, plant.D)[0]),
                               atol=1e-8)


class TestMinimalBalancedRealisation:
    @pytest.mark.parametrize("path", ["fb", "ff"])
    def test_gramians_equal_and_diagonal(self, path):
        m = appendix_a_model(path)
        balanced = lti.minimal_balanced_realisation(m.A, m.B, m.C, m.D)
        A, B, C, hsv = balanced.A, balanced.B, balanced.C, balanced.hankel_singular_values
        wc = scipy.linalg.solve_discrete_lyapunov(A, B @ B.T)
        wo = scipy.linalg.solve_discrete_lyapunov(A.T, C.T @ C)
        np.testing.assert_allclose(wc, np.diag(hsv), atol=1e-8 * hsv[0])
        np.testing.assert_allclose(wo, np.diag(hsv), atol=1e-8 * hsv[0])
        np.testing.assert_allclose(hsv, lti.hankel_singular_values(m.A, m.B, m.C), rtol=1e-6)

    def test_same_transfer_function(self):
        m = appendix_a_model("fb")
        balanced = lti.minimal_balanced_realisation(m.A, m.B, m.C, m.D)
        z = np.exp(1j * np.linspace(0.001, np.pi, 200))
        np.testing.assert_allclose(lti.frequency_response(balanced.A, balanced.B, balanced.C, balanced.D, z),
                                   lti.frequency_response(m.A, m.B, m.C, m.D, z), rtol=1e-8)

    def test_an_unobservable_state_is_left_out(self):
        # The second state is driven but never seen: G(z) = 1 / (z - 0.5), one state.
        A, B, C = np.diag([0.5, 0.8]), np.ones((2, 1)), np.array([[1.0, 0.0]])
        balanced = lti.minimal_balanced_realisation(A, B, C, 0.0)
        assert balanced.A.shape == (1, 1) and balanced.A[0, 0] == pytest.approx(0.5)
        assert balanced.B[0, 0] * balanced.C[0, 0] == pytest.approx(1.0)
        # Every Hankel singular value of the given system, the one left out (zero) included.
        assert balanced.hankel_singular_values.shape == (2,)
        assert balanced.hankel_singular_values[0] == pytest.approx(1.0 / (1.0 - 0.25))

    def test_order_keeps_the_largest_values_within_enns_bound(self):
        m = appendix_a_model("fb")
        full = lti.minimal_balanced_realisation(m.A, m.B, m.C, m.D)
        cut = lti.minimal_balanced_realisation(m.A, m.B, m.C, m.D, order=3)
        assert cut.A.shape == (3, 3) and cut.D == full.D
        np.testing.assert_array_equal(cut.hankel_singular_values, full.hankel_singular_values)
        error = np.abs(lti.frequency_response(cut.A, cut.B, cut.C, cut.D, Z)
                       - lti.frequency_response(full.A, full.B, full.C, full.D, Z))
        assert error.max() <= 2 * full.hankel_singular_values[3:].sum() * (1 + 1e-6)
