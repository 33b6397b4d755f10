"""Long responses: a least-squares FIR estimate and its frequency-limited balanced truncation.

Real acoustic paths (a headphone on an ear, a helmet liner, a head in a room) ring for
tens of milliseconds above a good microphone's noise and need hundreds of states. They
are reached without iterating:

1. ``fir_estimate``: the impulse response by least squares on the noise recording,
   g = argmin sum_t (y[t] - sum_k g_k u[t - k])^2 over taps k = -lead .. length - 1. The
   normal equations are Toeplitz in the input's autocorrelation (Ljung, "System
   Identification", 2nd ed., sec. 6.1 and 7.3) and are solved by Levinson recursion
   (``scipy.linalg.solve_toeplitz``) from correlations computed by FFT: O(N log N + L^2).
   The ``lead`` non-causal taps hold no response (the path is causal): they measure the
   estimate's own noise, in band, tap by tap (``noise_rms``).
2. ``frequency_limited_truncation``: a balanced truncation of the FIR over the band the data
   determine only (Gawronski & Juang, "Model reduction in limited time and frequency
   intervals", Int. J. Systems Sci. 21(2), 1990). The input is low-passed noise: above the
   band the estimate is noise amplified by the input's roll-off, and a plain balanced
   truncation spends its states on it (the HD 600's estimate: 18x the floor at 800 states).
   For the FIR in shift-register form (A the down-shift, B = e_1, C = g_1..g_L) the band's
   controllability Gramian is the sinc kernel P_ij = sin(w_b (i - j)) / (pi (i - j)), whose
   eigenvectors are the discrete prolate spheroidal sequences (Slepian 1978; ``scipy``'s
   ``dpss``), about 2 L f_b / fs of them with eigenvalues near one; the observability Gramian
   is H P H with H the taps' Hankel matrix. With P = Lp Lp^T the frequency-limited Hankel
   singular values are those of Lp^T H Lp (a square of about 2 L f_b / fs), and every order's
   realisation is a projection of the shift register. Truncation in a limited band is not
   stable by construction; ``realisation`` reflects a pole outside the unit circle into it
   and says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal.windows

from ..core import lti
from .subspace import fit_b_d

__all__ = ["FirEstimate", "fir_estimate", "FrequencyLimitedTruncation", "frequency_limited_truncation", "band_limited"]


@dataclass(frozen=True)
class FirEstimate:
    """Least-squares impulse response ``taps`` (FS per FS, taps 0 .. length - 1, the first at lag 0), the
    sample rate (Hz), and what sets its noise: the residual variance ``residual_variance`` (FS^2) over
    ``samples`` samples and the input's spectral density per sample ``input_psd`` (FS^2, on equally spaced
    frequencies from DC to fs / 2)."""

    taps: np.ndarray
    fs: float
    residual_variance: float
    samples: int
    input_psd: np.ndarray

    def noise_rms(self, band: tuple[float, float]) -> float:
        """RMS per tap (FS per FS) of the estimate's error inside ``band`` (Hz).

        The least-squares FIR's covariance is sigma^2 R^-1 / N (Ljung, sec. 9.2); over a band where the input
        spectrum Phi_u is smooth its band-limited part has per-tap variance sigma^2 / N times the band's mean
        of 1 / Phi_u over the whole frequency axis (the DFT of R is Phi_u).
        """
        f = np.linspace(0.0, self.fs / 2.0, self.input_psd.size)
        inside = (f >= band[0]) & (f <= band[1])
        share = np.sum(1.0 / self.input_psd[inside]) / (2.0 * (self.input_psd.size - 1))
        return float(np.sqrt(self.residual_variance / self.samples * 2.0 * share))


def band_limited(x: np.ndarray, fs: float, band: tuple[float, float]) -> np.ndarray:
    """x with its spectrum outside ``band`` (Hz) set to zero (zero phase, on a DFT of twice its length)."""
    n = 1 << int(np.ceil(np.log2(2 * x.size)))
    X = np.fft.rfft(x, n)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    X[(f < band[0]) | (f > band[1])] = 0.0
    return np.fft.irfft(X, n)[: x.size]


def _lagged_products(u: np.ndarray, end: int, length: int) -> np.ndarray:
    """M[d, k] = u[end - length + k] u[end - length + k - d] for lags d and positions k in 0 .. length - 1."""
    windows = np.lib.stride_tricks.sliding_window_view(u[end - 2 * length + 1: end], length)
    return u[end - length: end][None, :] * windows[::-1][:length]


def fir_estimate(u: np.ndarray, y: np.ndarray, fs: float, length: int, start: int | None = None) -> FirEstimate:
    """Least-squares FIR of ``length`` taps from input ``u`` and ear signal ``y`` of one recording (the delay
    already taken out; see the module docstring), fitted on the ear samples from ``start`` on.

    The samples before ``start`` (a noise recording's transient) serve as the input's history, so no ear sample
    is predicted from inputs that were not recorded; ``start`` defaults to ``2 length - 1``, the least the exact
    normal equations need (below). The normal equations
    are solved exactly (the covariance method): R_ij = sum_{t >= start} u[t - i] u[t - j] is the Toeplitz matrix
    of the lag products over t >= start less what the rows' shifted ranges leave out at the end and add at the
    start, O(length^2) from the lag products of the last and the first ``length`` samples. A Toeplitz
    approximation of R (the windowed method) is cheaper but inconsistent with the cross-correlation by
    O(length / N) where the low-passed input makes R ill-conditioned: 1.21x the floor instead of 1.02x on the
    HD 600's 2048 taps.
    """
    u = np.asarray(u, dtype=float) - np.mean(u)
    y = np.asarray(y, dtype=float) - np.mean(y)
    start = 2 * length - 1 if start is None else int(start)
    if start < 2 * length - 1 or y.size - start < 4 * length:
        raise ValueError(f"need at least {2 * length - 1} samples of history and {4 * length} to fit {length} taps; "
                         f"found {start} and {y.size - start}")
    n = y.size - start
    # c_k = sum_{t >= start} y[t] u[t - k] and r_k = sum_{t >= start} u[t] u[t - k], k = 0 .. length - 1, by FFT:
    # sum_t x[start + t] past[t + m] is lag k = length - 1 - m.
    past = u[start - length + 1:]
    nfft = 1 << int(np.ceil(np.log2(past.size + n)))
    P = np.fft.rfft(past, nfft)
    c = np.fft.irfft(np.conj(np.fft.rfft(y[start:], nfft)) * P, nfft)[:length][::-1]
    r = np.fft.irfft(np.conj(np.fft.rfft(u[start:], nfft)) * P, nfft)[:length][::-1]
    # R[i, i + d] = r_d - sum_{s = N - i}^{N - 1} u[s] u[s - d] + sum_{s = start - i}^{start - 1} u[s] u[s - d].
    tail = np.cumsum(_lagged_products(u, u.size, length)[:, ::-1], axis=1)
    head = np.cumsum(_lagged_products(u, start, length)[:, ::-1], axis=1)
    i, j = np.indices((length, length))
    lag, row = np.abs(i - j), np.minimum(i, j)
    shift = np.zeros((length, length))
    inside = row > 0
    shift[inside] = head[lag[inside], row[inside] - 1] - tail[lag[inside], row[inside] - 1]
    R = r[lag] + shift
    # A loading of 1e-9 of the input power keeps the factorisation regular where the low-passed input has no power
    # (far above its cut-off): a tap error of 1e-9 of the response, far below any output noise.
    R[np.diag_indices(length)] *= 1.0 + 1e-9
    g = scipy.linalg.solve(R, c, assume_a="pos")
    # Residual variance by the normal equations (R g = c): (y'y - g'c) over the fitted samples.
    variance = max((float(np.dot(y[start:], y[start:])) - float(np.dot(g, c))) / n, 0.0)
    # The input's spectral density per sample, Phi_u(w) = sum_k r_k e^{-jwk} / n, on 0..pi from its correlation.
    symmetric = np.concatenate((r, np.zeros(1), r[:0:-1])) / n
    psd = np.maximum(np.fft.rfft(symmetric).real, 1e-300)
    return FirEstimate(g, fs, variance, n, psd)


@dataclass
class FrequencyLimitedTruncation:
    """Every order's frequency-limited balanced truncation of one FIR (module docstring).

    ``hankel_singular_values``: the frequency-limited Hankel singular values, largest first;
    ``realisation(n)`` the order-n model (A, B, C, D) and the number of poles it reflected.
    """

    taps: np.ndarray
    fs: float
    band_hz: tuple[float, float]
    hankel_singular_values: np.ndarray
    _left: np.ndarray
    _right: np.ndarray

    @property
    def max_order(self) -> int:
        return int(self.hankel_singular_values.size)

    def realisation(self, n: int) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], int]:
        if not 1 <= n <= self.max_order:
            raise ValueError(f"order must lie in 1..{self.max_order}; found {n}")
        scale = 1.0 / np.sqrt(self.hankel_singular_values[:n])
        left = scale[:, None] * self._left[:n]          # n x L: projects the shift register's state
        right = self._right[:, :n] * scale[None, :]     # L x n
        # The down-shift applied to the right basis: (A_shift right)[i] = right[i - 1], zero in the first row.
        shifted = np.vstack((np.zeros((1, n)), right[:-1]))
        A = left @ shifted
        B = left[:, :1].copy()
        C = self.taps[None, 1:] @ right
        D = np.array([[self.taps[0]]])
        poles = np.linalg.eigvals(A)
        outside = np.abs(poles) >= 1.0
        if outside.any():
            return self._reflected(poles), int(outside.sum())
        return (A, B, C, D), 0

    def _reflected(self, poles: np.ndarray):
        """The poles outside the unit circle reflected into it (p -> 1 / conj(p): the same magnitude response
        up to a constant per pole), the numerator fitted again by least squares to the FIR's response in band
        (``subspace.fit_b_d``), then balanced."""
        poles = np.where(np.abs(poles) >= 1.0, 1.0 / np.conj(poles), poles)
        # Keep the reflected poles inside by the margin a least-squares fit needs to stay stable.
        poles = np.where(np.abs(poles) > 1.0 - 1e-9, poles / np.abs(poles) * (1.0 - 1e-9), poles)
        A = lti.real_block_diagonal(poles)
        C = lti.block_output_row(A)
        n_fft = 1 << int(np.ceil(np.log2(8 * self.taps.size)))
        f = np.fft.rfftfreq(n_fft, 1.0 / self.fs)
        inside = f <= self.band_hz[1]
        g = np.fft.rfft(self.taps, n_fft)[inside]
        B, D = fit_b_d(A, C, 2 * np.pi * f[inside] / self.fs, g, True)
        return lti.balanced_realisation(A, B, C, D)


def frequency_limited_truncation(taps: np.ndarray, fs: float, band: tuple[float, float],
                                 max_order: int | None = None) -> FrequencyLimitedTruncation:
    """Frequency-limited balanced truncation of the FIR ``taps`` (taps[0] the direct term) over ``band`` =
    (0, f_b) Hz (module docstring)."""
    taps = np.asarray(taps, dtype=float)
    L = taps.size - 1
    top = float(band[1])
    half_bandwidth = L * top / fs
    # The sinc kernel's eigenvalues fall from one to zero within a few around 2 L f_b / fs.
    count = min(L, int(np.ceil(2.0 * half_bandwidth)) + 40)
    vectors, ratios = scipy.signal.windows.dpss(L, half_bandwidth, Kmax=count, return_ratios=True)
    keep = ratios > 1e-12
    factor = vectors[keep].T * np.sqrt(ratios[keep])[None, :]      # L x K: P = factor factor^T
    hankel = scipy.linalg.hankel(taps[1:])
    observed = hankel @ factor                                        # L x K: H P H = observed observed^T
    u, s, vt = np.linalg.svd(observed.T @ factor)
    if max_order is not None:
        u, s, vt = u[:, :max_order], s[:max_order], vt[:max_order]
    left = u.T @ observed.T                                           # the left projection times sqrt(s)
    right = factor @ vt.T
    return FrequencyLimitedTruncation(taps, fs, (0.0, top), s, left, right)
