"""Tests of the Kautz basis and the block-wise least squares (anc.basis)."""

from __future__ import annotations

import numpy as np
import scipy.linalg

from anc.basis import KautzBasis, StateBasis, fit_blocks

FS = 48000.0
POLES = [0.9, -0.3, 0.95 * np.exp(0.2j), 0.7 * np.exp(2.0j), 0.0]


def test_the_state_space_realisation_has_the_basis_response():
    basis = KautzBasis.from_poles(POLES)
    c = np.linspace(-1.0, 1.0, basis.size)
    A, B, C, D = basis.statespace(c)
    f = np.linspace(0.0, FS / 2.0, 257)
    z = np.exp(2j * np.pi * f / FS)
    direct = np.array([(C @ np.linalg.solve(zk * np.eye(A.shape[0]) - A, B))[0, 0] + D[0, 0] for zk in z])
    np.testing.assert_allclose(basis.responses(f, FS) @ c, direct, atol=1e-10)


def test_the_functions_are_orthonormal():
    # Orthonormal in H2: the controllability Gramian of the cascade's states is the identity.
    A, B, _, _ = KautzBasis.from_poles(POLES).statespace(np.zeros(1 + 1 + 1 + 2 + 2 + 1))
    np.testing.assert_allclose(scipy.linalg.solve_discrete_lyapunov(A, B @ B.T), np.eye(A.shape[0]), atol=1e-10)


def test_block_least_squares_is_the_least_squares_solution():
    rng = np.random.default_rng(3)
    blocks = [(rng.standard_normal((200, 12)) + 1j * rng.standard_normal((200, 12)),
               rng.standard_normal(200) + 1j * rng.standard_normal(200)) for _ in range(3)]
    M = np.vstack([np.vstack([m.real, m.imag]) for m, _ in blocks])
    t = np.concatenate([np.concatenate([v.real, v.imag]) for _, v in blocks])
    np.testing.assert_allclose(fit_blocks(blocks, 12), np.linalg.lstsq(M, t, rcond=None)[0], atol=1e-12)


def test_poles_outside_the_unit_circle_are_refused():
    try:
        KautzBasis.from_poles([1.01])
    except ValueError as exc:
        assert "inside the unit circle" in str(exc)
    else:
        raise AssertionError("a pole at 1.01 was accepted")


def test_the_state_basis_realises_its_sum():
    # A non-normal A with a repeated pole at the origin (a delay line) beside a resonance.
    A = np.zeros((5, 5))
    A[1, 0] = A[2, 1] = 1.0
    A[3:, 3:] = [[1.8, -0.9], [1.0, 0.0]]
    A[3, 2] = 0.5
    B = np.array([[1.0], [0.0], [0.0], [0.2], [0.0]])
    z = np.exp(2j * np.pi * np.linspace(0.0, 0.5, 33))
    direct = np.stack([np.linalg.solve(zk * np.eye(5) - A, B[:, 0]) for zk in z], axis=1)
    basis = StateBasis(A, B)
    c = np.linspace(1.0, -1.0, basis.size)
    _, _, Cb, Db = basis.statespace(c)
    f = np.linspace(0.0, FS / 2.0, 33)
    np.testing.assert_allclose(basis.responses(f, FS) @ c, Cb[0] @ direct + Db[0, 0], rtol=1e-9, atol=1e-12)
