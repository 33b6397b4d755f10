"""Responses of single-input single-output discrete-time state-space systems.

The state-space convention is x(t+1) = A x(t) + B u(t), y(t) = C x(t) + D u(t)
(seed appendix A). Frequency responses and simulations go through the modal
(eigenvector) form, which turns an order-n system into n independent first-order
recursions; that is exact, vectorises over frequencies and time, and avoids the
high-order polynomials that the seed's appendix shows to be numerically unsafe.
When A is close to defective (ill-conditioned eigenvectors) the slower but always
well-posed direct forms are used instead. Realisations and balancing are in
:mod:`sysid.core.lti`, which also offers every name of this module.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal

__all__ = [
    "MAX_MODAL_CONDITION",
    "ModalForm",
    "as_siso",
    "frequency_response",
    "invariant_zeros",
    "modal_form",
    "modal_inverse",
    "pole_residue_response",
    "simulate",
    "state_responses",
]

# Above this eigenvector condition number the modal form loses more than about
# half of double precision; the direct forms are used instead.
MAX_MODAL_CONDITION = 1e8
# Points per block of ``pole_residue_response`` (its reciprocals, up to 30 poles, within 1 MB).
_RESPONSE_CHUNK = 2048
# Points per block of the Schur back substitution (n x points complex: 24 MB at 180 states).
_SCHUR_CHUNK = 8192


@dataclass(frozen=True)
class ModalForm:
    """G(z) = D + sum_i residues[i] / (z - poles[i]) with residues = (C V)_i (V^-1 B)_i."""

    poles: np.ndarray
    residues: np.ndarray
    d: float
    condition: float

    @property
    def reliable(self) -> bool:
        return bool(np.isfinite(self.condition) and self.condition < MAX_MODAL_CONDITION)


def as_siso(A, B, C, D):
    """(A, B, C, D) of a SISO system as float arrays of shapes (n, n), (n, 1), (1, n) and a float D."""
    A = np.atleast_2d(np.asarray(A, dtype=float))
    n = A.shape[0]
    B = np.asarray(B, dtype=float).reshape(n, 1) if n else np.zeros((0, 1))
    C = np.asarray(C, dtype=float).reshape(1, n) if n else np.zeros((1, 0))
    D = float(np.asarray(D, dtype=float).reshape(-1)[0])
    return A, B, C, D


def modal_inverse(V: np.ndarray) -> tuple[np.ndarray | None, float]:
    """V^-1 and the 1-norm condition number of V; None instead of V^-1 when the
    condition exceeds the modal form's limit (then the direct forms are used)."""
    try:
        V_inv = np.linalg.inv(V)
    except np.linalg.LinAlgError:
        return None, np.inf
    condition = float(np.linalg.norm(V, 1) * np.linalg.norm(V_inv, 1))
    if not (np.isfinite(condition) and condition < MAX_MODAL_CONDITION):
        return None, condition
    return V_inv, condition


def modal_form(A, B, C, D) -> ModalForm:
    """Partial-fraction (modal) form of a SISO state-space system (NaN residues if unreliable)."""
    A, B, C, D = as_siso(A, B, C, D)
    if A.shape[0] == 0:
        return ModalForm(np.zeros(0, complex), np.zeros(0, complex), D, 1.0)
    poles, V = np.linalg.eig(A)
    V_inv, condition = modal_inverse(V)
    if V_inv is None:
        return ModalForm(poles, np.full_like(poles, np.nan), D, condition)
    return ModalForm(poles, (C[0] @ V) * (V_inv @ B[:, 0]), D, condition)


def pole_residue_response(poles: np.ndarray, residues: np.ndarray, d, z: np.ndarray) -> np.ndarray:
    """G(z_k) = d + sum_i residues[i] / (z_k - poles[i]) for 1-D z; poles and residues (..., n) and d (...)
    may hold several models along their leading axes (the result is then (..., z.size)).

    The sum over the poles is a product of the reciprocals 1 / (z_k - p_i) with the residues,
    one model and ``_RESPONSE_CHUNK`` points at a time so that the reciprocals stay in cache: a
    fifth of the time of dividing each residue over all models and points at once.
    """
    poles = np.asarray(poles, dtype=complex)
    residues = np.asarray(residues, dtype=complex)
    z = np.asarray(z, dtype=complex).reshape(-1)
    lead = poles.shape[:-1]
    n = poles.shape[-1]
    # The models' count from the leading axes (reshape(-1, 0) cannot infer it for a static gain, n = 0).
    models = int(np.prod(lead, dtype=int))
    poles, residues = poles.reshape(models, n), residues.reshape(models, n)
    out = np.empty((poles.shape[0], z.size), dtype=complex)
    for k in range(poles.shape[0]):
        for start in range(0, z.size, _RESPONSE_CHUNK):
            reciprocal = z[start:start + _RESPONSE_CHUNK, None] - poles[k]
            np.reciprocal(reciprocal, out=reciprocal)
            out[k, start:start + _RESPONSE_CHUNK] = reciprocal @ residues[k]
    out += np.broadcast_to(np.asarray(d), lead).reshape(-1, 1)
    return out.reshape(*lead, z.size)


def frequency_response(A, B, C, D, z: np.ndarray) -> np.ndarray:
    """G(z) = C (zI - A)^-1 B + D at the complex points z (usually e^{j omega}).

    By the modal form where it is reliable, else by the complex Schur form A = U R U^H (backward stable) and
    back substitution over blocks of points, O(n^2) per point where a solve per point is O(n^3): a designed Q of
    180 states on the feed-forward design's 2^19-point grid (random pair 4/1005 of the control tests) took
    200 of its 230 CPU-s by dense solves."""
    A, B, C, D = as_siso(A, B, C, D)
    z = np.asarray(z, dtype=complex)
    modal = modal_form(A, B, C, D)
    if modal.reliable:
        return pole_residue_response(modal.poles, modal.residues, D, z.reshape(-1)).reshape(z.shape)
    R, U = scipy.linalg.schur(A, output="complex")
    b, c = U.conj().T @ B[:, 0], C[0] @ U
    flat = z.reshape(-1)
    out = np.empty(flat.size, dtype=complex)
    for start in range(0, flat.size, _SCHUR_CHUNK):
        zk = flat[start:start + _SCHUR_CHUNK]
        out[start:start + zk.size] = c @ _back_substitution(R, b, zk) + D
    return out.reshape(z.shape)


def state_responses(A: np.ndarray, B: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(n, len(z)) complex: (zI - A)^-1 B at many points z, by the complex Schur form (``frequency_response``)."""
    n = A.shape[0]
    z = np.asarray(z, dtype=complex).reshape(-1)
    if n == 0:
        return np.zeros((0, z.size), dtype=complex)
    R, U = scipy.linalg.schur(A, output="complex")
    b = U.conj().T @ np.asarray(B, dtype=float)[:, 0]
    out = np.empty((n, z.size), dtype=complex)
    for start in range(0, z.size, _SCHUR_CHUNK):
        zk = z[start:start + _SCHUR_CHUNK]
        out[:, start:start + zk.size] = U @ _back_substitution(R, b, zk)
    return out


def _back_substitution(R: np.ndarray, b: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(n, len(z)): x with (z I - R) x = b for an upper triangular R, at every point z at once."""
    n = R.shape[0]
    x = np.zeros((n, z.size), dtype=complex)
    for i in range(n - 1, -1, -1):
        x[i] = (b[i] + R[i, i + 1:] @ x[i + 1:]) / (z - R[i, i])
    return x


def simulate(A, B, C, D, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
    """Output y(t) of the system driven by u(t) from state x0 (zero by default)."""
    A, B, C, D = as_siso(A, B, C, D)
    u = np.asarray(u, dtype=float)
    n = A.shape[0]
    if n == 0:
        return D * u
    x0 = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float).reshape(n)
    poles, V = np.linalg.eig(A)
    V_inv, _ = modal_inverse(V)
    if V_inv is not None:
        b_modal = V_inv @ B[:, 0]
        x0_modal = V_inv @ x0
        c_modal = C[0] @ V
        t = np.arange(u.size)
        y = np.zeros(u.size)
        for p, b, c, x0_i in zip(poles, b_modal, c_modal, x0_modal):
            # Mode i: x_i(t+1) = p x_i(t) + b_i u(t), a first-order IIR. A real A gives
            # conjugate modes conjugate contributions (LAPACK returns conjugate
            # eigenvectors), so each pair is one filter counted twice in the real part.
            if p.imag < 0:
                continue
            # As a one-section sosfilt (a quarter less time than lfilter's general loop).
            if p.imag == 0:
                mode = scipy.signal.sosfilt([[0.0, b.real, 0.0, 1.0, -p.real, 0.0]], u)
                y += (c * mode).real if x0_i == 0 else (c * (mode + x0_i * p ** t)).real
            elif x0_i == 0:
                # The pair's real part from rest is one real second-order section, 2 Re(c b / (z - p)) =
                # (2 Re(g) z^-1 - 2 Re(g conj p) z^-2) / (1 - 2 Re(p) z^-1 + |p|^2 z^-2) with g = c b: half
                # the time of the complex first-order filter (random helmet 10, order 18, two 10 s sweeps:
                # 0.12 -> 0.06 s), the samples within 1e-13 of its largest.
                g = c * b
                y += scipy.signal.sosfilt([[0.0, 2 * g.real, -2 * (g * np.conj(p)).real, 1.0, -2 * p.real,
                                            abs(p) ** 2]], u)
            else:
                mode = scipy.signal.sosfilt([[0.0, b, 0.0, 1.0, -p, 0.0]], u.astype(complex))
                y += 2.0 * (c * (mode + x0_i * p ** t)).real
        return D * u + y
    if np.any(x0):
        _, y, _ = scipy.signal.dlsim((A, B, C, np.array([[D]]), 1.0), u, x0=x0)
        return y[:, 0]
    return D * u + _schur_response(A, B[:, 0], C[0], u)


def _schur_response(A: np.ndarray, b: np.ndarray, c: np.ndarray, u: np.ndarray) -> np.ndarray:
    """c x(t) of x(t+1) = A x(t) + b u(t) from rest, through the real Schur form A = Z T Z^T.

    For an A whose eigenvectors are too ill-conditioned for the modal form (coinciding poles):
    T is quasi-upper-triangular, so its diagonal blocks are filtered from the last one up, each
    driven by b's share and the already simulated later states (a 1 x 1 block is a first-order
    filter, a 2 x 2 block (zI - T_kk)^-1 = adj(zI - T_kk) / det(zI - T_kk) two second-order
    sections per state). Backward stable, and O(n^2) vector operations per sample block where
    ``scipy.signal.dlsim``'s loop over samples took 5 s per 10 s sweep (random helmet 41, order 21).
    """
    T, Z = scipy.linalg.schur(A, output="real")
    n = T.shape[0]
    drive = Z.T @ b
    states = np.zeros((n, u.size))
    k = n
    while k > 0:
        size = 2 if k >= 2 and T[k - 1, k - 2] != 0 else 1
        first = k - size
        w = drive[first:k, None] * u[None, :]
        if k < n:
            w = w + T[first:k, k:] @ states[k:]
        if size == 1:
            states[first] = scipy.signal.sosfilt([[0.0, 1.0, 0.0, 1.0, -T[first, first], 0.0]], w[0])
        else:
            (t11, t12), (t21, t22) = T[first:k, first:k]
            den = [1.0, -(t11 + t22), t11 * t22 - t12 * t21]
            states[first] = (scipy.signal.sosfilt([[0.0, 1.0, -t22, *den]], w[0])
                             + scipy.signal.sosfilt([[0.0, 0.0, t12, *den]], w[1]))
            states[first + 1] = (scipy.signal.sosfilt([[0.0, 0.0, t21, *den]], w[0])
                                 + scipy.signal.sosfilt([[0.0, 1.0, -t11, *den]], w[1]))
        k = first
    return (c @ Z) @ states


def invariant_zeros(A, B, C, D) -> np.ndarray:
    """Finite transmission zeros: generalised eigenvalues of the Rosenbrock pencil.

    Solves [A B; C D] v = z [I 0; 0 0] v, which avoids forming the numerator
    polynomial (rooting it loses the zeros of lightly damped high-order models).
    """
    A, B, C, D = as_siso(A, B, C, D)
    n = A.shape[0]
    if n == 0:
        return np.zeros(0, complex)
    M = np.block([[A, B], [C, np.array([[D]])]])
    N = np.zeros((n + 1, n + 1))
    N[:n, :n] = np.eye(n)
    values = scipy.linalg.eigvals(M, N)
    finite = np.isfinite(values) & (np.abs(values) < 1e8)
    return values[finite]
