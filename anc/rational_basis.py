"""Orthonormal rational basis with real poles (Takenaka-Malmquist), for the feedback filter's free part.

The functions (Ninness & Gustafsson, "A unifying construction of orthonormal bases for system
identification", IEEE Trans. Autom. Control 42(4), 1997, eq. 10; Heuberger, Van den Hof &
Wahlberg, "Modelling and Identification with Rational Orthogonal Basis Functions", Springer
2005, ch. 2)

.. math::
    \\phi_k(z) = \\frac{\\sqrt{1 - \\xi_k^2}}{z - \\xi_k}
                 \\prod_{j<k} \\frac{1 - \\xi_j z}{z - \\xi_j},
    \\qquad -1 < \\xi_k < 1,

are orthonormal on the unit circle, stable and real. With every pole equal they are the
Laguerre functions (``anc.basis``); with poles spread over the corner frequencies a filter
must resolve (here log-spaced from a few hertz to kilohertz, the set repeated: the
generalised orthonormal basis of Heuberger et al., ch. 3), a few hundred functions hold
responses with detail at 20 Hz and at 2 kHz alike, which one pole cannot.

``basis_poles`` places the poles; ``RationalBasis.responses`` evaluates the functions and
``RationalBasis.statespace`` realises a combination sum c_k phi_k as a state-space filter
(lower-triangular A with the poles on its diagonal: the functions' own cascade).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RationalBasis", "basis_poles"]


def basis_poles(fs: float, count: int, lowest_hz: float, highest_hz: float, per_cycle: int) -> np.ndarray:
    """``count`` real poles exp(-2 pi f / fs) for corner frequencies f log-spaced from ``lowest_hz`` to
    ``highest_hz`` in cycles of ``per_cycle`` (the set repeated, each cycle low to high)."""
    corners = np.geomspace(lowest_hz, highest_hz, per_cycle)
    return np.exp(-2.0 * np.pi * np.resize(corners, count) / fs)


@dataclass(frozen=True)
class RationalBasis:
    """The functions phi_1 .. phi_n of the real ``poles`` (module docstring)."""

    poles: tuple[float, ...]

    @classmethod
    def of(cls, poles) -> "RationalBasis":
        xi = np.asarray(poles, dtype=float).reshape(-1)
        if xi.size == 0 or np.any(np.abs(xi) >= 1.0):
            raise ValueError(f"a rational basis needs at least one pole, each inside the unit circle; found {xi}")
        return cls(tuple(float(v) for v in xi))

    @property
    def size(self) -> int:
        return len(self.poles)

    def responses(self, frequencies_hz, fs: float) -> np.ndarray:
        """Complex responses (len(f), size) of phi_1 .. phi_n at frequencies in Hz."""
        z = np.exp(2j * np.pi * np.asarray(frequencies_hz, dtype=float).reshape(-1) / fs)
        xi = np.asarray(self.poles)
        first = np.sqrt(1.0 - xi * xi)[None, :] / (z[:, None] - xi[None, :])
        allpass = (1.0 - xi[None, :] * z[:, None]) / (z[:, None] - xi[None, :])
        # phi_k = first_k * prod_{j<k} allpass_j: an exclusive cumulative product (unit modulus each).
        before = np.cumprod(np.hstack([np.ones((z.size, 1)), allpass[:, :-1]]), axis=1)
        return first * before

    def statespace(self, coefficients) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C, D) of sum c_k phi_k; state k is phi_k applied to the input.

        From (z - xi_1) x_1 = s_1 u and (z - xi_{k+1}) x_{k+1} = (s_{k+1} / s_k)(1 - xi_k z) x_k
        (s_k = sqrt(1 - xi_k^2)): x_{k+1}[t+1] = xi_{k+1} x_{k+1}[t] + (s_{k+1} / s_k)(x_k[t] - xi_k x_k[t+1]),
        so row k+1 of (A, B) is -(s_{k+1} / s_k) xi_k times row k plus the terms of x_k[t] and x_{k+1}[t].
        """
        c = np.asarray(coefficients, dtype=float).reshape(-1)
        if c.size != self.size:
            raise ValueError(f"expected {self.size} coefficients; found {c.size}")
        xi = np.asarray(self.poles)
        s = np.sqrt(1.0 - xi * xi)
        n = xi.size
        A = np.zeros((n, n))
        B = np.zeros((n, 1))
        A[0, 0], B[0, 0] = xi[0], s[0]
        for k in range(1, n):
            ratio = s[k] / s[k - 1]
            A[k] = -ratio * xi[k - 1] * A[k - 1]
            A[k, k - 1] += ratio
            A[k, k] += xi[k]
            B[k, 0] = -ratio * xi[k - 1] * B[k - 1, 0]
        return A, B, c.reshape(1, -1), np.zeros((1, 1))
