"""Responses of state-space systems (sysid.core.response), on systems whose answer is known."""

import numpy as np
import pytest
import scipy.signal

from sysid.core import lti, response

Z = np.exp(1j * np.linspace(0.001, np.pi - 0.001, 300))
# x(t+1) = 0.9 x(t) + 2 u(t), y = 0.5 x + 0.1 u: G(z) = 0.1 + 1 / (z - 0.9), h = [0.1, 1, 0.9, 0.81, ...].
FIRST_ORDER = ([[0.9]], [[2.0]], [[0.5]], 0.1)
# A Jordan block: eigenvectors too ill-conditioned for the modal form (the direct forms answer).
JORDAN = (np.array([[0.5, 1.0], [0.0, 0.5]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]), 0.0)


class TestFrequencyResponse:
    def test_first_order_system(self):
        np.testing.assert_allclose(response.frequency_response(*FIRST_ORDER, Z), 0.1 + 1.0 / (Z - 0.9), rtol=1e-12)

    def test_defective_system_through_the_direct_form(self):
        assert not response.modal_form(*JORDAN).reliable
        # (zI - A)^-1 B with C = [1, 0]: 1 / (z - 0.5)^2.
        np.testing.assert_allclose(response.frequency_response(*JORDAN, Z), 1.0 / (Z - 0.5) ** 2, rtol=1e-10)

    def test_a_delay_line_beside_a_resonance_over_several_blocks_of_points(self):
        # A non-normal A with a repeated pole at the origin (a delay line) beside a resonance: the modal form is
        # unreliable, the Schur back substitution answers, block by block, as a dense solve per point does.
        A = np.zeros((5, 5))
        A[1, 0] = A[2, 1] = 1.0
        A[3:, 3:] = [[1.8, -0.9], [1.0, 0.0]]
        A[3, 2] = 0.5
        B = np.array([[1.0], [0.0], [0.0], [0.2], [0.0]])
        C = np.array([[0.3, -1.0, 0.5, 0.2, 1.0]])
        assert not response.modal_form(A, B, C, 0.1).reliable
        z = np.exp(1j * np.linspace(0.0, np.pi, 3 * response._SCHUR_CHUNK + 5))
        every = slice(None, None, 97)
        direct = np.stack([np.linalg.solve(zk * np.eye(5) - A, B[:, 0]) for zk in z[every]], axis=1)
        np.testing.assert_allclose(response.state_responses(A, B, z)[:, every], direct, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(response.frequency_response(A, B, C, 0.1, z)[every], C[0] @ direct + 0.1,
                                   rtol=1e-9, atol=1e-12)

    def test_keeps_the_shape_of_z(self):
        z = Z[:12].reshape(3, 4)
        assert response.frequency_response(*FIRST_ORDER, z).shape == (3, 4)


class TestSimulate:
    def test_impulse_response_of_a_first_order_system(self):
        u = np.zeros(20)
        u[0] = 1.0
        expected = np.concatenate(([0.1], 0.9 ** np.arange(19)))
        np.testing.assert_allclose(response.simulate(*FIRST_ORDER, u), expected, rtol=1e-12, atol=1e-15)

    def test_initial_state_decays_geometrically(self):
        y = response.simulate(*FIRST_ORDER, np.zeros(10), x0=[4.0])
        np.testing.assert_allclose(y, 0.5 * 4.0 * 0.9 ** np.arange(10), rtol=1e-12)

    def test_defective_system_matches_dlsim(self):
        u = np.random.default_rng(1).standard_normal(200)
        A, B, C, D = JORDAN
        _, expected, _ = scipy.signal.dlsim((A, B, C, np.array([[D]]), 1.0), u)
        np.testing.assert_allclose(response.simulate(*JORDAN, u), expected[:, 0], rtol=1e-9, atol=1e-12)

    def test_static_gain(self):
        np.testing.assert_array_equal(response.simulate(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), 2.0,
                                                        np.arange(4.0)), 2.0 * np.arange(4.0))


class TestModalForm:
    def test_residues_of_a_first_order_system(self):
        modal = response.modal_form(*FIRST_ORDER)
        assert modal.reliable
        np.testing.assert_allclose(modal.poles, [0.9])
        np.testing.assert_allclose(modal.residues, [1.0])
        assert modal.d == 0.1

    def test_pole_residue_response_of_several_models(self):
        poles = np.array([[0.5, 0.2], [0.9, -0.3]])
        residues = np.array([[1.0, 2.0], [0.5, 0.25]])
        d = np.array([0.0, 1.0])
        out = response.pole_residue_response(poles, residues, d, Z)
        assert out.shape == (2, Z.size)
        for k in range(2):
            expected = d[k] + sum(r / (Z - p) for p, r in zip(poles[k], residues[k]))
            np.testing.assert_allclose(out[k], expected, rtol=1e-12)

    def test_modal_inverse_refuses_an_ill_conditioned_basis(self):
        V_inv, condition = response.modal_inverse(np.array([[1.0, 1.0], [0.0, 1e-12]]))
        assert V_inv is None and condition > response.MAX_MODAL_CONDITION


def test_invariant_zeros_of_a_known_transfer_function():
    # G(z) = (z - 0.3) / ((z - 0.5) (z - 0.6)) in controllable canonical form.
    A = np.array([[1.1, -0.3], [1.0, 0.0]])
    B = np.array([[1.0], [0.0]])
    C = np.array([[1.0, -0.3]])
    np.testing.assert_allclose(response.invariant_zeros(A, B, C, 0.0), [0.3], rtol=1e-10)


@pytest.mark.parametrize("name", response.__all__)
def test_every_name_is_still_offered_by_lti(name):
    assert getattr(lti, name) is getattr(response, name)
