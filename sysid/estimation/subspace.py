"""Frequency-domain subspace identification from FRF samples (McKelvey, Akcay & Ljung 1996).

Given samples G_k of a frequency response at arbitrary (non-uniform) normalised
frequencies omega_k (rad/sample), k = 1..M, find a real order-n model
G(z) = C (zI - A)^-1 B + D. Algorithm 2 of McKelvey, Akcay & Ljung, IEEE TAC 41(7),
1996, pp. 960-979, which the seed (section 3.3.1) follows:

1. Data matrices with q block rows, scaled by 1/sqrt(M):
   G_q[i, k] = e^{j i omega_k} G_k and W_q[i, k] = e^{j i omega_k}, i = 0..q-1.
2. Real QR (as an LQ factorisation) of [Re W_q, Im W_q; Re G_q, Im G_q] = L Q^T;
   L22 carries the part of G_q orthogonal to the input rows.
3. Noise weighting K K^T = Re(W_q diag(R_k) W_q^*) (R_k the variance of G_k; one
   when unknown), SVD K^-1 L22 = U S V^T. The singular values S are the order plot.
4. Extended observability matrix O = K U[:, :n]; C = first row, A from the shift
   property O[1:] = O[:-1] A by least squares.
5. B, D by linear least squares on sum_k |G_k - D - C (z_k I - A)^-1 B|^2 with
   z_k = e^{j omega_k}, real and imaginary parts stacked.

Steps 1-3 do not depend on n: ``SubspaceDecomposition`` does them once and gives
every order from the same SVD.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..core import lti
from ..core.errors import IdentificationError

__all__ = ["SubspaceDecomposition", "SubspaceFit", "subspace_fit", "fit_b_d", "stabilise", "data_subspace_poles",
           "reflect_unstable"]


@dataclass(frozen=True)
class SubspaceFit:
    """An order-n model from the subspace method and what was done to make it stable."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    stable: bool
    stabilisation: str  # "none", "reflected k pole(s)", or "unstable (left as is)"
    # G(z) = D + sum residues / (z - poles), when the eigenvectors of A are well conditioned.
    poles: np.ndarray | None = None
    residues: np.ndarray | None = None


def fit_b_d(A: np.ndarray, C: np.ndarray, omega: np.ndarray, g: np.ndarray, feedthrough: bool,
            weights: np.ndarray | None = None, eig=None) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares B (n x 1) and D (1 x 1) for fixed A, C on FRF samples (step 5).

    ``eig`` may pass a precomputed (poles, eigenvectors) of A.
    """
    z = np.exp(1j * omega)
    return _solve_b_d(_observation_rows(A, C, z, eig), g, feedthrough, weights)


def _solve_b_d(phi: np.ndarray, g: np.ndarray, feedthrough: bool, weights: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """B, D minimising sum_k |w_k (g_k - D - phi_k B)|^2 (step 5), real and imaginary parts stacked."""
    n = phi.shape[1]
    columns = [phi] + ([np.ones((g.size, 1))] if feedthrough else [])
    regressor = np.hstack(columns)
    target = g.copy()
    if weights is not None:
        regressor = regressor * weights[:, None]
        target = target * weights
    real = np.vstack([regressor.real, regressor.imag])
    rhs = np.concatenate([target.real, target.imag])
    theta, *_ = np.linalg.lstsq(real, rhs, rcond=None)
    B = theta[:n].reshape(n, 1)
    D = np.array([[theta[n] if feedthrough else 0.0]])
    return B, D


def _observation_rows(A: np.ndarray, C: np.ndarray, z: np.ndarray, eig=None) -> np.ndarray:
    """Rows C (z_k I - A)^-1 (M x n): by the eigenvectors of A, by solves if A is near-defective."""
    n = A.shape[0]
    poles, V = eig if eig is not None else np.linalg.eig(A)
    V_inv, _ = lti.modal_inverse(V)
    if V_inv is not None:
        return ((C[0] @ V)[None, :] / (z[:, None] - poles[None, :])) @ V_inv
    eye = np.eye(n)
    return np.linalg.solve((z[:, None, None] * eye - A).transpose(0, 2, 1), np.broadcast_to(C[0], (z.size, n))[..., None])[..., 0]


def stabilise(A, C, omega, g, feedthrough, method: str = "reflect", weights=None) -> SubspaceFit:
    """Fit B, D for A, C; if A is unstable, handle it by ``method``.

    'reflect': poles p with |p| >= 1 are replaced by 1/conj(p) (same magnitude
    response shape up to a gain), the model is rebuilt in real block-diagonal form
    and B, D are re-estimated by least squares. 'keep': return the unstable model,
    flagged. 'reject': raise IdentificationError.
    """
    poles = np.linalg.eigvals(A) if A.shape[0] else np.zeros(0)
    unstable = np.abs(poles) >= 1.0
    if not np.any(unstable):
        B, D = fit_b_d(A, C, omega, g, feedthrough, weights)
        return SubspaceFit(A, B, C, D, True, "none")
    if method == "keep":
        B, D = fit_b_d(A, C, omega, g, feedthrough, weights)
        return SubspaceFit(A, B, C, D, False, "unstable (left as is)")
    if method == "reject":
        raise IdentificationError(f"identified model is unstable (largest pole radius {np.abs(poles).max():.6f})")
    if method != "reflect":
        raise IdentificationError(f"stability method must be reflect, keep or reject; found {method!r}")
    reflected = np.where(unstable, 1.0 / np.conj(poles), poles)
    # A pole exactly on the unit circle stays there after reflection; pull it inside.
    reflected = np.where(np.abs(reflected) >= 1.0, reflected * (1 - 1e-6) / np.abs(reflected), reflected)
    A_new = lti.real_block_diagonal(reflected)
    C_new = lti.block_output_row(A_new)
    B, D = fit_b_d(A_new, C_new, omega, g, feedthrough, weights)
    return SubspaceFit(A_new, B, C_new, D, True, f"reflected {int(unstable.sum())} pole(s) into the unit circle")


def reflect_unstable(poles: np.ndarray, max_radius: float = 0.99995) -> tuple[np.ndarray, int]:
    """Poles with |p| >= 1 replaced by 1/conj(p) (radius capped at max_radius), and how many moved."""
    poles = np.asarray(poles, dtype=complex)
    unstable = np.abs(poles) >= 1.0
    reflected = np.where(unstable, 1.0 / np.conj(np.where(poles == 0, 1.0, poles)), poles)
    radius = np.abs(reflected)
    reflected = np.where(radius > max_radius, reflected * max_radius / np.maximum(radius, 1e-300), reflected)
    return reflected, int(unstable.sum())


def data_subspace_poles(z: np.ndarray, U: np.ndarray, Y: np.ndarray, orders, q: int | None = None) -> dict[int, np.ndarray]:
    """Poles of every order in ``orders`` from raw input/output DFT data (no smoothing).

    McKelvey, Akcay & Ljung (1996), Algorithm 1 (the input/output-data variant), with the
    block's transient as an extra input: Y_k = G(z_k) U_k + C (z_k I - A)^-1 z_k x_delta,
    so the input rows are [z_k^i U_k; z_k^i], i = 0..q-1, and the output rows z_k^i Y_k.
    1. Real LQ factorisation of [inputs; outputs]; L22 holds the output part orthogonal
       to both inputs. 2. SVD of L22; the observability matrix of order n is U[:, :n].
    3. A from the shift property by least squares; its eigenvalues are returned (the
       rest of the model follows linearly, see ``output_error``). Unlike the smoothed-FRF
       variant this has no smoothing bias at lightly damped modes.
    """
    z = np.asarray(z, dtype=complex)
    orders = [int(n) for n in orders]
    q = q or max(orders) + 10
    if 2 * z.size < 3 * q:
        raise IdentificationError(f"need at least {3 * q // 2 + 1} DFT bins for q={q}; found {z.size}")
    powers = np.exp(1j * np.outer(np.arange(q), np.angle(z))) / np.sqrt(z.size)
    scale_u = np.sqrt(np.mean(np.abs(U) ** 2)) or 1.0
    scale_y = np.sqrt(np.mean(np.abs(Y) ** 2)) or 1.0
    rows = np.vstack([powers * (U / scale_u)[None, :], powers, powers * (Y / scale_y)[None, :]])
    stacked = np.hstack([rows.real, rows.imag])
    r = scipy.linalg.qr(stacked.T, mode="r", check_finite=False)[0]
    l22 = r[2 * q:3 * q, 2 * q:3 * q].T
    u, _, _ = np.linalg.svd(l22)
    out = {}
    for n in orders:
        if not 1 <= n < q:
            raise IdentificationError(f"order must be between 1 and q-1 = {q - 1}; found {n}")
        o = u[:, :n]
        A = np.linalg.lstsq(o[:-1], o[1:], rcond=None)[0]
        out[n] = np.linalg.eigvals(A)
    return out


class SubspaceDecomposition:
    """Steps 1-3 of the algorithm for one set of FRF samples; ``fit(n)`` does steps 4-5."""

    def __init__(self, omega, g, q: int = 30, noise_variance=None, feedthrough: bool = False):
        omega = np.asarray(omega, dtype=float)
        g = np.asarray(g, dtype=complex)
        if omega.shape != g.shape or omega.ndim != 1:
            raise IdentificationError("frequencies and FRF samples must be 1-D arrays of one length")
        if not np.all(np.isfinite(g)):
            raise IdentificationError("FRF samples contain NaN or infinite values")
        if q < 2 or 2 * omega.size < q:
            raise IdentificationError(f"need 2 <= q <= 2 M; found q={q} with M={omega.size} frequencies")
        self.omega, self.g, self.q, self.feedthrough = omega, g, q, feedthrough
        m = omega.size
        # 1. Data matrices.
        powers = np.exp(1j * np.outer(np.arange(q), omega)) / np.sqrt(m)
        w_q = powers
        g_q = powers * g[None, :]
        # 2. LQ factorisation of the real stacked matrix, via QR of its transpose.
        stacked = np.vstack([np.hstack([w_q.real, w_q.imag]), np.hstack([g_q.real, g_q.imag])])
        r = scipy.linalg.qr(stacked.T, mode="r")[0]
        l22 = r[q:2 * q, q:2 * q].T
        # 3. Noise weighting and SVD.
        variance = np.ones(m) if noise_variance is None else np.asarray(noise_variance, dtype=float)
        self.weights = None if noise_variance is None else 1.0 / np.sqrt(variance)
        kk = ((w_q * variance[None, :]) @ w_q.conj().T).real
        self.k = np.linalg.cholesky(kk + 1e-12 * np.trace(kk) / q * np.eye(q))
        u, s, _ = np.linalg.svd(scipy.linalg.solve_triangular(self.k, l22, lower=True))
        self.singular_values = s
        self._u = u
        # 4. (for every order at once) O_n = K U[:, :n] are nested, so one QR of the
        # largest O[:-1] = Q R gives every shift-property solution
        # A_n = R[:n, :n]^-1 (Q^T O[1:])[:n, :n].
        observability = self.k @ u[:, : q - 1]
        self._shift_q, self._shift_r = np.linalg.qr(observability[:-1])
        self._shift_rhs = self._shift_q.T @ observability[1:]
        self._observability = observability

    @property
    def max_order(self) -> int:
        return self.q - 1

    def observability(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """A and C of order n (step 4)."""
        if not 1 <= n <= self.max_order:
            raise IdentificationError(f"order must be between 1 and q-1 = {self.max_order}; found {n}")
        o = self._observability[:, :n]
        r = self._shift_r[:n, :n]
        diagonal = np.abs(np.diag(r))
        if diagonal.min() > 1e-10 * diagonal.max():
            A = scipy.linalg.solve_triangular(r, self._shift_rhs[:n, :n], check_finite=False)
        else:  # O[:-1] is (nearly) rank deficient: let least squares pick the minimum-norm A.
            A = np.linalg.lstsq(o[:-1], o[1:], rcond=None)[0]
        return A, o[:1]

    def fit_if_stable(self, n: int) -> SubspaceFit | None:
        """The order-n model if its A is stable, else None (the seed's grid keeps stable models only)."""
        A, C = self.observability(n)
        poles, V = np.linalg.eig(A)
        if np.max(np.abs(poles)) >= 1.0:
            return None
        B, D = fit_b_d(A, C, self.omega, self.g, self.feedthrough, self.weights, eig=(poles, V))
        V_inv, _ = lti.modal_inverse(V)
        residues = None if V_inv is None else (C[0] @ V) * (V_inv @ B[:, 0])
        return SubspaceFit(A, B, C, D, True, "none", poles, residues)

    @staticmethod
    def fits_if_stable(decompositions: list["SubspaceDecomposition"], n: int) -> list[SubspaceFit | None]:
        """``fit_if_stable(n)`` of each of ``decompositions``, by one LAPACK call per step for all of them.

        The seed's grid fits every order at a hundred smoothing widths of one set of frequencies:
        a call per candidate spent most of its time in the calls' own overhead. Batched: the
        shift-property solves (``np.linalg.solve`` on R: its LU has no row exchanges, the entries below
        R's diagonal being zero, and is the back substitution of ``observability``), the
        eigendecompositions and the inverses of the eigenvectors;
        candidates outside the batched path (an ill-conditioned R or V, other frequencies,
        weights) go through ``fit_if_stable`` one by one.
        """
        out: list[SubspaceFit | None] = [None] * len(decompositions)
        first = decompositions[0] if decompositions else None
        batchable = [i for i, d in enumerate(decompositions)
                     if d.weights is None and d.feedthrough == first.feedthrough and 1 <= n <= d.max_order
                     and (d.omega is first.omega or np.array_equal(d.omega, first.omega))]
        single = sorted(set(range(len(decompositions))) - set(batchable))
        if batchable:
            r = np.stack([decompositions[i]._shift_r[:n, :n] for i in batchable])
            rhs = np.stack([decompositions[i]._shift_rhs[:n, :n] for i in batchable])
            diagonal = np.abs(np.diagonal(r, axis1=1, axis2=2))
            solvable = diagonal.min(axis=1) > 1e-10 * diagonal.max(axis=1)
            single += [i for i, ok in zip(batchable, solvable) if not ok]
            batchable = [i for i, ok in zip(batchable, solvable) if ok]
            A = np.linalg.solve(r[solvable], rhs[solvable])
        if batchable:
            C = np.stack([decompositions[i]._observability[:1, :n] for i in batchable])
            poles, V = np.linalg.eig(A)
            stable = np.max(np.abs(poles), axis=1) < 1.0
            try:
                V_inv = np.linalg.inv(V[stable])
            except np.linalg.LinAlgError:  # a singular V among them: one by one
                single += [i for i, ok in zip(batchable, stable) if ok]
                stable[:] = False
            else:
                condition = np.abs(V[stable]).sum(axis=1).max(axis=1) * np.abs(V_inv).sum(axis=1).max(axis=1)
                modal = np.isfinite(condition) & (condition < lti.MAX_MODAL_CONDITION)
                single += [i for i, ok in zip(np.asarray(batchable)[stable], modal) if not ok]
                V_inv = V_inv[modal]
                stable[np.flatnonzero(stable)[~modal]] = False
            if np.any(stable):
                keep = np.flatnonzero(stable)
                A, C, poles, V = A[keep], C[keep], poles[keep], V[keep]
                # 5. B, D (``fit_b_d`` with the eigenvectors, ``_observation_rows``), for each candidate.
                cv = (C @ V)[:, 0, :]
                z = np.exp(1j * first.omega)
                rows = (cv[:, None, :] / (z[None, :, None] - poles[:, None, :])) @ V_inv
                for k, index in enumerate(np.asarray(batchable)[keep]):
                    B, D = _solve_b_d(rows[k], decompositions[index].g, first.feedthrough, None)
                    residues = cv[k] * (V_inv[k] @ B[:, 0])
                    out[index] = SubspaceFit(A[k], B, C[k], D, True, "none", poles[k], residues)
        for i in single:
            out[i] = decompositions[i].fit_if_stable(n)
        return out

    def fit(self, n: int, stability: str = "reflect") -> SubspaceFit:
        """The order-n model (steps 4-5) with stability handled by ``stability``."""
        A, C = self.observability(n)
        return stabilise(A, C, self.omega, self.g, self.feedthrough, stability, self.weights)


def subspace_fit(omega, g, n: int, q: int | None = None, feedthrough: bool = False, stability: str = "reflect",
                 noise_variance=None) -> SubspaceFit:
    """One order-n fit to FRF samples g at omega (rad/sample); see the module docstring."""
    q = q or max(2 * n + 2, 30)
    return SubspaceDecomposition(omega, g, q, noise_variance, feedthrough).fit(n, stability)
