"""Realisations of single-input single-output discrete-time state-space systems, and all balancing.

The state-space convention is x(t+1) = A x(t) + B u(t), y(t) = C x(t) + D u(t)
(seed appendix A). Here: stability (``spectral_radius``), real block-diagonal and
chained realisations, Gramians and Hankel singular values, and every balanced
realisation of the project: identification's (``balanced_realisation``,
``balanced_truncation``) and the minimal one of code generation and controller
design (``minimal_balanced_realisation``). Frequency responses, simulation and
zeros live in :mod:`sysid.core.response`; their names are offered here too, where
the rest of the package has always imported them from.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from .response import (MAX_MODAL_CONDITION, ModalForm, as_siso, frequency_response, invariant_zeros, modal_form,
                       modal_inverse, pole_residue_response, simulate, state_responses)

__all__ = [
    "ModalForm",
    "modal_form",
    "modal_inverse",
    "MAX_MODAL_CONDITION",
    "block_output_row",
    "pole_residue_response",
    "frequency_response",
    "simulate",
    "state_responses",
    "invariant_zeros",
    "spectral_radius",
    "real_block_diagonal",
    "gramians",
    "hankel_singular_values",
    "balanced_realisation",
    "balanced_truncation",
    "chained_realisation",
    "equalise_states",
    "MinimalBalanced",
    "minimal_balanced_realisation",
]

# Real poles closer than this fraction of their distance 1 - |p| from the unit circle are chained
# (``chained_realisation``).
_CLUSTER_GAP = 0.1


def spectral_radius(A) -> float:
    """Largest pole modulus max |eig(A)| (0 for a static system)."""
    A = np.atleast_2d(np.asarray(A, dtype=float))
    if A.shape[0] == 0:
        return 0.0
    return float(np.max(np.abs(np.linalg.eigvals(A))))


def real_block_diagonal(poles: np.ndarray) -> np.ndarray:
    """Real A matrix with the given (conjugate-closed) poles as 1x1 and 2x2 blocks."""
    poles = np.asarray(poles, dtype=complex)
    A = np.zeros((poles.size, poles.size))
    used = np.zeros(poles.size, dtype=bool)
    k = 0
    for i, p in enumerate(poles):
        if used[i]:
            continue
        used[i] = True
        if abs(p.imag) < 1e-12 * max(1.0, abs(p)):
            A[k, k] = p.real
            k += 1
            continue
        candidates = np.where(~used)[0]
        j = candidates[np.argmin(np.abs(poles[candidates] - np.conj(p)))]
        used[j] = True
        A[k:k + 2, k:k + 2] = [[p.real, p.imag], [-p.imag, p.real]]
        k += 2
    return A


def block_output_row(A_block: np.ndarray) -> np.ndarray:
    """C = [1 0 | 1 0 | 1 | ...]: observable for a real block-diagonal A with distinct poles."""
    n = A_block.shape[0]
    C = np.zeros((1, n))
    i = 0
    while i < n:
        C[0, i] = 1.0
        i += 2 if i + 1 < n and A_block[i, i + 1] != 0 else 1
    return C


def gramians(A, B, C) -> tuple[np.ndarray, np.ndarray]:
    """Controllability and observability Gramians of a stable system.

    W_c = A W_c A^T + B B^T and W_o = A^T W_o A + C^T C (discrete Lyapunov equations),
    symmetrised against round-off.
    """
    A, B, C, _ = as_siso(A, B, C, 0.0)
    wc = scipy.linalg.solve_discrete_lyapunov(A, B @ B.T)
    wo = scipy.linalg.solve_discrete_lyapunov(A.T, C.T @ C)
    return (wc + wc.T) / 2, (wo + wo.T) / 2


def hankel_singular_values(A, B, C) -> np.ndarray:
    """sigma_i = sqrt(eig(W_c W_o)), largest first, of a stable system.

    A state whose sigma is far below the others contributes little to the
    input-output behaviour; balanced truncation removes it with an error bound of
    twice the sum of the removed sigmas.
    """
    if spectral_radius(A) >= 1.0:
        raise ValueError("Hankel singular values need a stable model (all poles inside the unit circle)")
    wc, wo = gramians(A, B, C)
    values = np.sqrt(np.abs(np.linalg.eigvals(wc @ wo)))
    return np.sort(values.real)[::-1]


def _gramian_factor(W: np.ndarray) -> np.ndarray:
    """L with L L^H = W for a Hermitian positive semi-definite W (eigenvalues below zero by round-off clipped)."""
    values, vectors = np.linalg.eigh(W)
    return vectors * np.sqrt(np.clip(values, 0.0, None))[None, :]


def equalise_states(A, B, C, D):
    """A diagonal similarity T = diag(t) giving every state (every 2x2 block of a real
    block-diagonal A) equal input and output gains, |(T^-1 B)_block| = |(C T)_block|.

    Scaling both states of a block by one factor leaves a rotation block [[a, b], [-b, a]]
    unchanged, so A keeps its form; only B and C change. A block is a pair of states
    coupled in A; other couplings get the factor of their own states.
    """
    A, B, C, D = as_siso(A, B, C, D)
    n = A.shape[0]
    t = np.ones(n)
    i = 0
    while i < n:
        width = 2 if i + 1 < n and (A[i, i + 1] != 0 or A[i + 1, i] != 0) else 1
        b = np.linalg.norm(B[i:i + width, 0])
        c = np.linalg.norm(C[0, i:i + width])
        if b > 0 and c > 0:
            t[i:i + width] = np.sqrt(b / c)
        i += width
    return A / t[:, None] * t[None, :], B / t[:, None], C * t[None, :], np.array([[D]])


def _pole_clusters(poles: np.ndarray) -> list[np.ndarray]:
    """Indices of ``poles`` in clusters (single linkage: poles closer than _CLUSTER_GAP times their
    distance 1 - |p| from the unit circle belong to one), each sorted by real, then imaginary part."""
    n = poles.size
    near = np.abs(poles[:, None] - poles[None, :]) < _CLUSTER_GAP * (1.0 - np.abs(poles))[:, None]
    label = -np.ones(n, dtype=int)
    for i in range(n):
        if label[i] >= 0:
            continue
        label[i], stack = i, [i]
        while stack:
            j = stack.pop()
            for k in np.flatnonzero((near[j] | near[:, j]) & (label < 0)):
                label[k] = i
                stack.append(k)
    clusters = [np.flatnonzero(label == i) for i in np.unique(label)]
    return [c[np.lexsort((poles[c].imag, poles[c].real))] for c in clusters]


def chained_realisation(A, B, C, D):
    """A realisation of a stable SISO system in which nearly coincident poles form chains, or None
    when its modal form is unreliable (``ModalForm.reliable``); complex where a cluster holds
    complex poles (``_square_root_balance`` makes the balanced result real).

    A modal (diagonal) realisation of a cluster of close poles p_1 .. p_m needs residues r_i
    that grow like 1 / prod |p_i - p_j| and cancel (random helmet 79, short session: seven real
    poles within 6e-4 of 0.9887, residues of 2e4; 17: a pair 0.51155 +- 3.7e-5j beside real
    poles at 0.5117 and 0.5134, residues of 3e7); its Gramians lose their small eigenvalues to
    round-off, so it cannot be balanced. The Newton basis phi_k = alpha^(k-1) / prod_{j<=k}
    (z - p_j) holds the same cluster with coefficients of the size of the response: it is the
    chain x_1(t+1) = p_1 x_1 + u, x_k(t+1) = p_k x_k + alpha x_(k-1), with
    sum_i r_i / (z - p_i) = sum_k d_k / prod_{j<=k} (z - p_j), d_k = sum_{i>=k} r_i
    prod_{j<k} (p_i - p_j) (from 1/(z - a) = sum_k prod_{j<k} (a - p_j) / prod_{j<=k} (z - p_j),
    which ends at p_k = a): products of the poles' small differences, no division by them.
    alpha = 1 - |p| at the cluster's mean gives every link a gain of order one at the
    cluster's frequency. A complex pair alone stays a real 2 x 2 rotation block (C = [1, 0],
    B = [2 Re r, -2 Im r] for the residue r of p = a + jb, the block [[a, b], [-b, a]]), a real
    pole alone a 1 x 1 block.
    """
    A, B, C, D = as_siso(A, B, C, D)
    modal = modal_form(A, B, C, D)
    if not modal.reliable or modal.poles.size == 0:
        return None
    poles, residues = modal.poles, modal.residues
    n = poles.size
    real = np.abs(poles.imag) < 1e-12 * np.maximum(1.0, np.abs(poles))
    clusters = _pole_clusters(poles)
    dtype = complex if any(c.size > 1 and not np.all(real[c]) for c in clusters) else float
    Ac, Bc, Cc = np.zeros((n, n), dtype), np.zeros((n, 1), dtype), np.zeros((1, n), dtype)
    k = 0
    for indices in clusters:
        if indices.size == 1 and not real[indices[0]]:
            p, r = poles[indices[0]], residues[indices[0]]
            if p.imag < 0:
                continue  # the pair's block comes with its upper pole
            Ac[k:k + 2, k:k + 2] = [[p.real, p.imag], [-p.imag, p.real]]
            Bc[k:k + 2, 0] = [2 * r.real, -2 * r.imag]
            Cc[0, k] = 1.0
            k += 2
            continue
        cluster, r = poles[indices], residues[indices]
        if dtype is float:
            cluster, r = cluster.real, r.real
        m = cluster.size
        alpha = max(1.0 - abs(cluster.mean()), 1e-12)
        d = np.array([np.sum(r[j:] * np.prod(cluster[j:, None] - cluster[None, :j], axis=1)) for j in range(m)])
        Ac[k:k + m, k:k + m] = np.diag(cluster) + np.diag(np.full(m - 1, alpha), -1)
        Bc[k, 0] = 1.0
        Cc[0, k:k + m] = d / alpha ** np.arange(m)
        k += m
    if k != n:
        return None
    return Ac, Bc, Cc, np.array([[D]])


def _square_root_balance(A, B, C, D, reference: np.ndarray, z: np.ndarray, rtol: float, truncate: float = 0.0,
                         order: int | None = None):
    """Tombs & Postlethwaite's square-root balancing of (A, B, C, D), or None when the result's response
    at z differs from ``reference`` by more than rtol of its peak. With ``truncate`` > 0 the states whose
    Hankel singular values lie below ``truncate`` times the largest are left out (balanced truncation),
    and with ``order`` all but the first ``order``; the response may then differ by twice the sum of
    the removed values more (the bound of balanced truncation, discrete time as continuous: Al-Saggaf
    & Franklin, IEEE Trans. Autom. Control 32(9), 1987). Without either, a state below 1e-13 of the
    largest gives None (it cannot be balanced).

    A complex realisation (``chained_realisation``) balances to a real system's balanced realisation
    times a diagonal of unit phases (for distinct Hankel singular values): the phases that make B real
    and positive leave it real, and its imaginary round-off is dropped (the response check decides)."""
    complex_input = np.iscomplexobj(A) or np.iscomplexobj(B) or np.iscomplexobj(C)
    # The conjugate transpose; a real system's steps exactly as for a real one (the same products in the
    # same memory layout, so the same last bits: the output-error fits that follow amplify them).
    H = (lambda M: M.conj().T) if complex_input else (lambda M: M.T)
    try:
        if complex_input:
            wc = scipy.linalg.solve_discrete_lyapunov(A, B @ H(B))
            wo = scipy.linalg.solve_discrete_lyapunov(H(A), H(C) @ C)
            wc, wo = (wc + H(wc)) / 2, (wo + H(wo)) / 2
        else:
            wc, wo = gramians(A, B, C)
        lc, lo = _gramian_factor(wc), _gramian_factor(wo)
        u, s, vt = np.linalg.svd(H(lo) @ lc)
    except (np.linalg.LinAlgError, ValueError, scipy.linalg.LinAlgError):
        return None
    if not np.all(np.isfinite(s)) or s[0] <= 0:
        return None
    keep = s.size if truncate <= 0 else int(np.count_nonzero(s >= truncate * s[0]))
    if order is not None:
        keep = min(keep, order)
    if keep < 1 or s[keep - 1] < 1e-13 * s[0]:
        return None
    root = 1.0 / np.sqrt(s[:keep])
    T = lc @ H(vt[:keep]) * root[None, :]
    T_inv = root[:, None] * (H(u[:, :keep]) @ H(lo))
    Ab, Bb, Cb = T_inv @ A @ T, T_inv @ B, C @ T
    if complex_input:
        phase = np.exp(-1j * np.angle(Bb[:, 0]))
        Ab, Bb, Cb = (phase[:, None] * Ab * np.conj(phase)[None, :]).real, (phase[:, None] * Bb).real, \
            (Cb * np.conj(phase)[None, :]).real
    after = frequency_response(Ab, Bb, Cb, D[0, 0].real, z)
    allowed = rtol * max(np.max(np.abs(reference)), 1e-300) + 2.0 * np.sum(s[keep:])
    if not np.all(np.isfinite(after)) or np.max(np.abs(after - reference)) > allowed:
        return None
    if keep < s.size and spectral_radius(Ab) >= 1.0:
        # Truncated by Gramians that round-off dominates (a balanced truncation of a stable system is stable).
        return None
    return Ab, Bb, Cb, D.real


def balanced_truncation(A, B, C, D, tol: float = 1e-10, rtol: float = 1e-5, order: int | None = None):
    """The balanced realisation of a stable SISO system without its states whose Hankel singular
    values lie below ``tol`` times the largest, and of at most ``order`` states (Moore 1981; the
    H-infinity error is at most twice the sum of the removed values), or None when no such
    realisation reproduces the frequency response on 512 points of the unit circle within ``rtol``
    of the peak gain plus that bound.

    The states left out carry nothing of the input-output behaviour: a cluster of close real
    poles that an output-error fit placed where fewer poles would do (random helmet 79, short
    session: seven poles within 6e-4 of 0.9887, Hankel singular values down to 1e-17 of the
    largest in their ``chained_realisation``) has no balanced realisation of its full order.
    """
    A, B, C, D = equalise_states(A, B, C, D)
    if A.shape[0] == 0 or spectral_radius(A) >= 1.0:
        return None
    z = np.exp(1j * np.pi * (np.arange(512) + 0.5) / 512)
    reference = frequency_response(A, B, C, D[0, 0], z)
    # From the chain realisation first: the Gramians of a modal form with large cancelling residues are
    # round-off below their largest eigenvalues, and a truncation by them can match the response on the
    # circle and still hold an unstable pole (random helmet 17, short: |p| = 1.005 with a tiny residue).
    chained = chained_realisation(A, B, C, D)
    truncated = None if chained is None else _square_root_balance(*chained, reference, z, rtol, tol, order)
    if truncated is None:
        truncated = _square_root_balance(A, B, C, D, reference, z, rtol, tol, order)
    if truncated is not None and truncated[0].shape[0] < A.shape[0]:
        # A discrete-time balanced truncation is stable but not balanced itself (its Gramians differ from
        # the kept block of the full ones): balanced once more at its own order.
        own = frequency_response(*truncated[:3], truncated[3][0, 0], z)
        truncated = _square_root_balance(*truncated, own, z, rtol) or truncated
    return truncated


def balanced_realisation(A, B, C, D, rtol: float = 1e-5):
    """The balanced realisation of a stable SISO system (Moore 1981; square-root method of
    Tombs & Postlethwaite, Int. J. Control 46(4), 1987).

    With the Gramians W_c = L_c L_c^T, W_o = L_o L_o^T (``gramians``) and the SVD
    L_o^T L_c = U S V^T, T = L_c V S^-1/2 and T^-1 = S^-1/2 U^T L_o^T give
    (T^-1 A T, T^-1 B, C T, D), whose two Gramians both equal S = diag(Hankel singular
    values). A is then a contraction and |B_i|, |C_i| <= sqrt(sigma_i) (from
    S = A S A^T + B B^T = A^T S A + C^T C): every entry is of order one whatever the
    scaling of the input realisation (a modal form with a unit output row puts all gain
    into B, up to 1e12 for nearly coincident poles).
    A system with a Hankel singular value below 1e-13 of the largest (a state that
    carries nothing of the input-output behaviour) cannot be balanced, and an unstable
    one has no Gramians: both are returned in the ``equalise_states`` form. So is a
    result whose frequency response on 512 points of the unit circle differs from the
    input's by more than ``rtol`` of the peak gain (Gramians lost to round-off, mostly
    close poles with large cancelling residues). The equalised block-diagonal form keeps
    such poles exactly, where a balanced A would hold them only to about 1e-4 (clustered
    eigenvalues of a dense matrix), so fits refined further start from the poles they
    found; a model leaving identification is balanced from its chain realisation instead
    (``balanced_truncation``, ``sysid.estimation.reduction``).
    """
    A, B, C, D = equalise_states(A, B, C, D)
    n = A.shape[0]
    if n == 0 or spectral_radius(A) >= 1.0:
        return A, B, C, D
    z = np.exp(1j * np.pi * (np.arange(512) + 0.5) / 512)
    reference = frequency_response(A, B, C, D[0, 0], z)
    balanced = _square_root_balance(A, B, C, D, reference, z, rtol)
    return (A, B, C, D) if balanced is None else balanced


@dataclass(frozen=True)
class MinimalBalanced:
    """A balanced minimal realisation (``minimal_balanced_realisation``) and the Hankel singular values
    of the system it was computed from: all n of them, largest first, also those of the states left out."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: float
    hankel_singular_values: np.ndarray


def _cholesky_factor(W: np.ndarray) -> np.ndarray:
    """Upper factor R with W = R^T R, robust to a Gramian that is only semi-definite (then from its
    eigenvalues clipped at zero)."""
    try:
        return scipy.linalg.cholesky(W, lower=False)
    except np.linalg.LinAlgError:
        values, vectors = np.linalg.eigh(W)
        values = np.clip(values, 0.0, None)
        return (vectors * np.sqrt(values)).T


def minimal_balanced_realisation(A, B, C, D, order: int | None = None) -> MinimalBalanced:
    """The balanced realisation of a stable SISO system without its uncontrollable or unobservable
    states, optionally truncated to ``order`` states (Moore 1981; square-root algorithm of Laub,
    Heath, Paige & Ward, IEEE Trans. Autom. Control 32(2), 1987).

    With the Gramians W_c = L_c L_c^T, W_o = L_o L_o^T (``gramians``, Cholesky factors) and the
    SVD L_o^T L_c = U S V^T, the balancing transformation is T = L_c V S^-1/2 with inverse
    S^-1/2 U^T L_o^T. States whose Hankel singular value is at most 1e-14 of the largest are
    always dropped; with ``order`` only the first ``order`` are kept, and the H-infinity error is
    at most twice the sum of the values left out (Enns' bound).

    The realisation firmware generation (``codegen.realise``) and controller design (``anc.design``)
    use. Unlike identification's ``balanced_realisation`` it takes the system as given (no
    ``equalise_states`` first), drops states instead of refusing to balance them, and does not
    check the result's response: the generated code and the controllers' stored filters are
    defined by this arithmetic, so the two are kept apart rather than merged.
    """
    A = np.asarray(A, float)
    B = np.asarray(B, float).reshape(-1, 1)
    C = np.asarray(C, float).reshape(1, -1)
    wc, wo = gramians(A, B, C)
    lc = _cholesky_factor(wc).T
    lo = _cholesky_factor(wo).T
    U, s, Vt = np.linalg.svd(lo.T @ lc)
    keep = int(np.sum(s > 1e-14 * s[0])) if s.size and s[0] > 0 else 0
    if order is not None:
        keep = min(keep, int(order))
    s_half = np.sqrt(s[:keep])
    T = lc @ Vt[:keep].T / s_half
    T_inv = (U[:, :keep] / s_half).T @ lo.T
    return MinimalBalanced(A=T_inv @ A @ T, B=T_inv @ B, C=C @ T, D=float(np.asarray(D).reshape(-1)[0]),
                           hankel_singular_values=s)
