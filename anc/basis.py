"""Rational filter bases (Laguerre; Kautz with any poles) and the weighted least-squares fits in them.

Both controller filters are written as Q(z) = c_0 + sum_{i=1}^{n} c_i L_i(z) with the
discrete Laguerre functions (Heuberger, Van den Hof & Wahlberg, "Modelling and
Identification with Rational Orthogonal Basis Functions", Springer 2005, ch. 2):

.. math::
    L_i(z) = \\frac{\\sqrt{1 - a^2}}{z - a} \\left( \\frac{1 - a z}{z - a} \\right)^{i-1},
    \\qquad 0 \\le a < 1 .

A Laguerre series is an FIR filter on a warped frequency axis: with the pole a at a few
hundred hertz, n = 32 functions resolve the 20 Hz - 2 kHz range that an FIR of the same
length (resolution fs / n, over 1 kHz) cannot. Every filter of the family is stable (all
poles at a) and linear in c, so a frequency-weighted quadratic criterion has a closed-form
minimum (``fit``).

Optionally (``highpass_hz``) every function is multiplied by a fixed second-order high-pass
with a double zero at DC,

.. math::
    H(z) = \\left( \\frac{1 + b}{2} \\, \\frac{1 - z^{-1}}{1 - b z^{-1}} \\right)^2,
    \\qquad b = e^{-2 \\pi f_h / f_s},

(unit gain at fs / 2) so the filter has no gain at DC whatever its coefficients: the
feedback filter needs that below the identified band, where the model is an extrapolation
and the true path may be large (the seed's FB path has a pole at 0.9999).

``KautzBasis``: the orthonormal basis of Takenaka and Malmquist for any stable poles
(Heuberger, Van den Hof & Wahlberg 2005, ch. 2 and 3; Ninness & Gustafsson, IEEE Trans.
Autom. Control 42(4), 1997), realised as a cascade of balanced all-pass sections, one per
real pole or complex pair: each section's system matrix [[A_k, B_k], [C_k, D_k]] is
orthogonal, so the cascade's states are orthonormal in H2 (their controllability Gramian is
the identity; Roberts & Mullis, "Digital Signal Processing", 1987, sec. 9.10) and a filter
D + sum c_i x_i is linear in (D, c). With poles placed from the paths' dynamics it holds a
Wiener filter in a few hundred functions where a Laguerre series needs thousands, and its
realisation is well conditioned at any size (no powers of a companion matrix). ``qr_blocks`` /
``fit_blocks`` solve a weighted least-squares problem on a long grid by a QR factorisation
updated one block of frequencies at a time, so memory stays at (block, functions) whatever the grid.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg
import scipy.signal

from sysid.core.lti import state_responses

__all__ = ["LaguerreBasis", "KautzBasis", "StateBasis", "fit", "fit_blocks", "qr_blocks"]


@dataclass(frozen=True)
class LaguerreBasis:
    """The constant plus ``order`` Laguerre functions with pole ``pole`` (0 <= pole < 1)."""

    pole: float
    order: int
    highpass_pole: float | None = None

    @classmethod
    def at(cls, corner_hz: float, order: int, fs: float, highpass_hz: float | None = None) -> "LaguerreBasis":
        """Basis whose pole sits at corner_hz: a = exp(-2 pi corner_hz / fs); with highpass_hz, the
        DC-blocking factor H (module docstring) with b = exp(-2 pi highpass_hz / fs)."""
        b = None if highpass_hz is None else float(np.exp(-2.0 * np.pi * highpass_hz / fs))
        return cls(float(np.exp(-2.0 * np.pi * corner_hz / fs)), int(order), b)

    def _highpass(self) -> tuple[np.ndarray, np.ndarray]:
        """(numerator, denominator) in z^-1 of the DC-blocking factor H."""
        b = self.highpass_pole
        g = ((1.0 + b) / 2.0) ** 2
        return g * np.array([1.0, -2.0, 1.0]), np.array([1.0, -2.0 * b, b * b])

    @property
    def size(self) -> int:
        """Number of coefficients (the constant and the Laguerre functions)."""
        return self.order + 1

    def responses(self, frequencies_hz, fs: float) -> np.ndarray:
        """Complex responses (len(f), size) of [1, L_1, ..., L_n] at frequencies in Hz."""
        z = np.exp(2j * np.pi * np.asarray(frequencies_hz, dtype=float) / fs)
        a = self.pole
        first = np.sqrt(1.0 - a * a) / (z - a)
        allpass = (1.0 - a * z) / (z - a)
        powers = allpass[:, None] ** np.arange(self.order)[None, :]
        result = np.hstack([np.ones((z.size, 1)), first[:, None] * powers])
        if self.highpass_pole is not None:
            num, den = self._highpass()
            zi = 1.0 / z
            result = result * (np.polyval(num[::-1], zi) / np.polyval(den[::-1], zi))[:, None]
        return result

    def statespace(self, coefficients) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C, D) of c_0 + sum c_i L_i; state i is L_i applied to the input.

        From (z - a) x_1 = sqrt(1 - a^2) u and (z - a) x_{i+1} = (1 - a z) x_i:
        x_{i+1}[k+1] = a x_{i+1}[k] + x_i[k] - a x_i[k+1], so row i+1 of (A, B) is
        -a times row i plus the identity terms; A is lower triangular with a on the diagonal.
        """
        c = np.asarray(coefficients, dtype=float).reshape(-1)
        if c.size != self.size:
            raise ValueError(f"expected {self.size} coefficients; found {c.size}")
        n, a = self.order, self.pole
        A = np.zeros((n, n))
        B = np.zeros((n, 1))
        A[0, 0], B[0, 0] = a, np.sqrt(1.0 - a * a)
        for i in range(1, n):
            A[i] = -a * A[i - 1]
            A[i, i - 1] += 1.0
            A[i, i] += a
            B[i, 0] = -a * B[i - 1, 0]
        C, D = c[1:].reshape(1, -1), c[:1].reshape(1, 1)
        if self.highpass_pole is None:
            return A, B, C, D
        # Series: the Laguerre sum, then H (state [x_laguerre; x_h]).
        Ah, Bh, Ch, Dh = scipy.signal.tf2ss(*self._highpass())
        top = np.hstack([A, np.zeros((n, 2))])
        bottom = np.hstack([Bh @ C, Ah])
        return (np.vstack([top, bottom]), np.vstack([B, Bh @ D]), np.hstack([Dh @ C, Ch]), Dh @ D)


def fit(responses: np.ndarray, gain: np.ndarray, target: np.ndarray, weight: np.ndarray,
        penalty: np.ndarray, constraints=None) -> np.ndarray:
    """Real coefficients c minimising a frequency-weighted quadratic criterion.

    .. math::
        J(c) = \\sum_k w_k \\, |g_k F_k(c) + t_k|^2 + \\sum_k \\rho_k \\, |F_k(c)|^2,
        \\qquad F_k(c) = \\sum_i c_i \\Phi_{ki}

    with the basis responses Phi (``responses``), the fixed factor g (``gain``), the target
    t (``target``), weights w >= 0 and penalties rho >= 0 per frequency. Solved by the
    normal equations of the real-valued problem (J is quadratic in the real vector c).

    ``constraints``: optional convex quadratic constraints c' A c + b' c <= limit (A positive
    semi-definite, limit >= 0, so c = 0 is feasible), as (A, b, limit) tuples; J is then
    minimised under them by the log-barrier method (``_barrier``) in coordinates where J is
    |z - g|^2 (Cholesky factor of the normal matrix), started from c = 0.
    """
    M = gain[:, None] * responses
    weighted = M.conj().T * weight
    normal = np.real(weighted @ M) + np.real((responses.conj().T * penalty) @ responses)
    rhs = -np.real(weighted @ target)
    scale = np.trace(normal) / normal.shape[0]
    normal = normal + 1e-12 * scale * np.eye(normal.shape[0])
    free = np.linalg.solve(normal, rhs)
    if not constraints:
        return free
    # J - const = c' N c - 2 rhs' c; in z = R c (N = R' R, Cholesky) it is |z|^2 - 2 g' z with
    # g = R^-T rhs, well conditioned whatever the basis; its unconstrained minimum is -|g|^2.
    R = np.linalg.cholesky(normal).T
    g = scipy.linalg.solve_triangular(R, rhs, trans="T")
    Rinv = scipy.linalg.solve_triangular(R, np.eye(R.shape[0]))
    quads = [(Rinv.T @ A @ Rinv, Rinv.T @ b, limit) for A, b, limit in constraints]
    return Rinv @ _barrier(g, quads)


def _barrier(g: np.ndarray, quads) -> np.ndarray:
    """argmin |z|^2 - 2 g' z subject to z' A z + b' z <= limit for each (A, b, limit) of ``quads``
    (convex, z = 0 strictly feasible when every limit > 0): the log-barrier method (Boyd &
    Vandenberghe, "Convex Optimization", 2004, sec. 11.3), Newton steps kept strictly feasible by
    backtracking, the barrier weight 1/t divided by 10 per round down to a duality gap of
    m / t <= 1e-6 of the unconstrained minimum |g|^2 (the objective is divided by it)."""
    z = np.zeros_like(g)
    unit = max(float(g @ g), 1e-300)
    m = len(quads)
    if m == 0 or min(limit for _, _, limit in quads) <= 0.0:
        return z

    def slack(v):
        return np.array([limit - v @ A @ v - b @ v for A, b, limit in quads])

    t = 1.0
    while m / t > 1e-6:
        for _ in range(50):
            s = slack(z)
            grads = np.array([2.0 * A @ z + b for A, b, _ in quads])
            gradient = t / unit * (2.0 * z - 2.0 * g) + np.sum(grads / s[:, None], axis=0)
            hessian = 2.0 * t / unit * np.eye(z.size) + sum(2.0 * A / si for (A, _, _), si in zip(quads, s)) \
                + (grads / s[:, None]).T @ (grads / s[:, None])
            step = -np.linalg.solve(hessian, gradient)
            decrement = float(-gradient @ step)
            if decrement / 2.0 <= 1e-10:
                break
            size = 1.0
            while np.any(slack(z + size * step) <= 0.0) and size > 1e-12:
                size *= 0.5
            value = t / unit * (z @ z - 2.0 * g @ z) - np.sum(np.log(s))
            while size > 1e-12:
                trial = z + size * step
                st = slack(trial)
                if np.all(st > 0.0) and (t / unit * (trial @ trial - 2.0 * g @ trial) - np.sum(np.log(st))
                                         <= value - 0.25 * size * decrement):
                    break
                size *= 0.5
            if size <= 1e-12:
                break
            z = z + size * step
        t *= 10.0
    return z


def _allpass_section(poles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Real (A, B, C, D) with an orthogonal system matrix of the all-pass prod (1 - conj(p) z) / (z - p)
    over one real pole or one complex pair (``poles`` of length 1 or 2)."""
    if poles.size == 1:
        a = float(poles[0].real)
        g = np.sqrt(1.0 - a * a)
        return np.array([[a]]), np.array([[g]]), np.array([[g]]), np.array([[-a]])
    p = complex(poles[0])
    # (1 - p z)(1 - conj(p) z) / ((z - p)(z - conj(p))) = (r2 z^2 - 2 re z + 1) / (z^2 - 2 re z + r2).
    re, r2 = p.real, abs(p) ** 2
    num, den = np.array([r2, -2.0 * re, 1.0]), np.array([1.0, -2.0 * re, r2])
    A, B, C, D = scipy.signal.tf2ss(num, den)
    # Balance it: an all-pass's balanced realisation has unit Gramians and an orthogonal system matrix.
    wc = scipy.linalg.solve_discrete_lyapunov(A, B @ B.T)
    wo = scipy.linalg.solve_discrete_lyapunov(A.T, C.T @ C)
    lc = np.linalg.cholesky((wc + wc.T) / 2.0)
    lo = np.linalg.cholesky((wo + wo.T) / 2.0)
    U, s, Vt = np.linalg.svd(lo.T @ lc)
    T = lc @ Vt.T / np.sqrt(s)
    T_inv = (U / np.sqrt(s)).T @ lo.T
    return T_inv @ A @ T, T_inv @ B, C @ T, D


@dataclass(frozen=True)
class KautzBasis:
    """The constant plus the orthonormal functions of ``poles`` (complex poles in conjugate pairs,
    all inside the unit circle); see the module docstring. ``size`` = 1 + len(poles)."""

    poles: tuple

    @classmethod
    def from_poles(cls, poles) -> "KautzBasis":
        """The basis of the given poles (real ones and one of each conjugate pair, or both)."""
        poles = np.asarray(poles, dtype=complex).reshape(-1)
        if poles.size and np.max(np.abs(poles)) >= 1.0:
            raise ValueError(f"Kautz poles must lie inside the unit circle; found radius {np.max(np.abs(poles)):.6f}")
        real = poles[np.abs(poles.imag) <= 1e-12 * np.maximum(np.abs(poles), 1e-300)].real
        upper = poles[poles.imag > 1e-12 * np.maximum(np.abs(poles), 1e-300)]
        return cls(tuple(complex(p) for p in real) + tuple(complex(p) for p in upper))

    @property
    def sections(self) -> list[np.ndarray]:
        return [np.array([p]) if p.imag == 0.0 else np.array([p, p.conjugate()]) for p in self.poles]

    @cached_property
    def _realisations(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        return [_allpass_section(poles) for poles in self.sections]

    @property
    def size(self) -> int:
        return 1 + sum(s.size for s in self.sections)

    def responses(self, frequencies_hz, fs: float) -> np.ndarray:
        """Complex responses (len(f), size) of [1, x_1, ..., x_n] at frequencies in Hz."""
        z = np.exp(2j * np.pi * np.asarray(frequencies_hz, dtype=float) / fs)
        columns = [np.ones(z.size, dtype=complex)]
        into = np.ones(z.size, dtype=complex)
        for poles, (A, B, C, D) in zip(self.sections, self._realisations):
            if poles.size == 1:
                states = (B[0, 0] / (z - A[0, 0]))[:, None]
            else:
                # (z I - A)^-1 B for a 2 x 2 A, by its adjugate.
                det = (z - A[0, 0]) * (z - A[1, 1]) - A[0, 1] * A[1, 0]
                states = np.stack(((z - A[1, 1]) * B[0, 0] + A[0, 1] * B[1, 0],
                                   A[1, 0] * B[0, 0] + (z - A[0, 0]) * B[1, 0]), axis=1) / det[:, None]
            states = states * into[:, None]
            columns.extend(states.T)
            into = states @ C[0] + D[0, 0] * into
        return np.stack(columns, axis=1)

    def statespace(self, coefficients) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C, D) of c_0 + sum c_i x_i: the cascade's states, section after section."""
        c = np.asarray(coefficients, dtype=float).reshape(-1)
        if c.size != self.size:
            raise ValueError(f"expected {self.size} coefficients; found {c.size}")
        n = self.size - 1
        A, B = np.zeros((n, n)), np.zeros((n, 1))
        # The input of the current section as (row over the states so far, gain on the filter input).
        row, gain = np.zeros(n), 1.0
        at = 0
        for poles, (Ak, Bk, Ck, Dk) in zip(self.sections, self._realisations):
            k = slice(at, at + poles.size)
            A[k] += np.outer(Bk[:, 0], row)
            A[k, k] += Ak
            B[k, 0] = Bk[:, 0] * gain
            row = Dk[0, 0] * row
            row[k] += Ck[0]
            gain = Dk[0, 0] * gain
            at += poles.size
        return A, B, c[1:].reshape(1, -1), c[:1].reshape(1, 1)


@dataclass(frozen=True)
class StateBasis:
    """The constant and the states of a stable (A, B) as a basis, W = D + C x: a truncated filter's poles with
    its output weights free (``anc.feedforward`` refits them when the board's order cap is reached)."""

    A: np.ndarray
    B: np.ndarray

    @property
    def size(self) -> int:
        return self.A.shape[0] + 1

    def responses(self, frequencies_hz, fs: float) -> np.ndarray:
        """Complex responses (len(f), size) of [1, x_1, ..., x_n] at frequencies in Hz."""
        z = np.exp(2j * np.pi * np.asarray(frequencies_hz, dtype=float).reshape(-1) / fs)
        return np.hstack([np.ones((z.size, 1), dtype=complex), state_responses(self.A, self.B, z).T])

    def statespace(self, coefficients) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C, D) of c_0 + sum c_i x_i."""
        c = np.asarray(coefficients, dtype=float).reshape(-1)
        if c.size != self.size:
            raise ValueError(f"expected {self.size} coefficients; found {c.size}")
        return self.A, self.B, c[1:].reshape(1, -1), c[:1].reshape(1, 1)


def qr_blocks(rows, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(R, h) with |M x - t|^2 = |R x - h|^2 + const for the real x, from an iterable of complex blocks
    (M_b, t_b), M_b of shape (m_b, size): Householder QR of the stacked real and imaginary parts,
    updated block by block (Golub & Van Loan, "Matrix Computations", 4th ed., sec. 5.2), so memory
    stays at one block whatever the grid."""
    # The right-hand side rides along as the last column: R of [M | t] is [[R, Q' t], [0, residual]], so Q is
    # never formed.
    augmented = np.zeros((0, size + 1))
    for M, t in rows:
        block = np.hstack([np.vstack([M.real, M.imag]), np.concatenate([t.real, t.imag])[:, None]])
        augmented = np.linalg.qr(np.vstack([augmented, block]), mode="r")[: size + 1]
    return augmented[:size, :size], augmented[:size, size]


def fit_blocks(rows, size: int) -> np.ndarray:
    """Real x minimising sum over blocks of |M_b x - t_b|^2 (``qr_blocks``), of least norm among directions the
    data do not determine (singular values of R below 1e-12 of the largest dropped)."""
    R, h = qr_blocks(rows, size)
    U, s, Vt = np.linalg.svd(R, full_matrices=False)
    keep = s > 1e-12 * s[0] if s.size and s[0] > 0 else np.zeros(s.shape, bool)
    return Vt[keep].T @ ((U[:, keep].T @ h) / s[keep])
