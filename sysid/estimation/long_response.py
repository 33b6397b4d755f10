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

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.signal.windows

from ..core import lti
from .subspace import fit_b_d

# Points per block of ``system_response``'s back substitution (its work array within a few MB at hundreds of states).
_POINTS = 1024

__all__ = ["FirEstimate", "fir_estimate", "FrequencyLimitedTruncation", "frequency_limited_truncation",
           "system_response", "band_limited"]


@dataclass(frozen=True)
class FirEstimate:
    """Least-squares impulse response ``taps`` (FS per FS, taps 0 .. length - 1, the first at lag 0), the
    sample rate (Hz), and what sets its noise: the residual variance ``residual_variance`` (FS^2) over
    ``samples`` samples and the input's spectral density per sample ``input_psd`` (FS^2, on equally spaced
    frequencies from DC to fs / 2).

    The nested fits of the same normal equations (module docstring, step 1):
    ``residual_energy[l]`` (FS^2, summed over the fitted samples) is the residual of the least-squares FIR of the
    first l taps, l = 0 .. length (``residual_energy[length]`` the estimate's own); ``lead_energy(m)[d]`` the rise
    of the estimate's residual when its first d taps are held at zero and the others refitted, d = 0 .. m. Under the hypothesis that those taps are zero, either rise (against the longest
    fit's residual) over the residual variance is chi-square with as many degrees of freedom as taps left out,
    whatever the input's spectrum (the F-test of nested linear models; Soederstroem & Stoica, "System
    Identification", 1989, sec. 11.5).
    """

    taps: np.ndarray
    fs: float
    residual_variance: float
    samples: int
    input_psd: np.ndarray
    residual_energy: np.ndarray
    # The Cholesky factor of the normal equations and L^-1 c (``fir_estimate``): every nested fit from them.
    _factor: np.ndarray = field(repr=False)
    _projection: np.ndarray = field(repr=False)

    @property
    def length(self) -> int:
        return int(self.taps.size)

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

    def lead_energy(self, m: int) -> np.ndarray:
        """Rise of the residual (FS^2 over the fitted samples) when the first d taps are held at zero and the others
        refitted, d = 0 .. m (``fir_estimate``'s docstring has the method)."""
        m = min(int(m), self.length)
        if m <= 0:
            return np.zeros(1)
        columns = scipy.linalg.solve_triangular(self._factor, np.eye(self.length, m), lower=True, check_finite=False)
        t = scipy.linalg.qr(columns, mode="r", check_finite=False)[0][:m]
        w = scipy.linalg.solve_triangular(t, self.taps[:m], trans="T", lower=False, check_finite=False)
        return np.concatenate(([0.0], np.cumsum(w**2)))

    def nested(self, length: int) -> np.ndarray:
        """The taps of the least-squares FIR of the first ``length`` taps on the same samples (its residual is
        ``residual_energy[length]``). Not the first taps of this estimate: cut there, their error's large
        content above the input's band (the input has no power there) would leak into the band."""
        length = int(length)
        if not 0 <= length <= self.length:
            raise ValueError(f"length must lie in 0..{self.length}; found {length}")
        return scipy.linalg.solve_triangular(self._factor[:length, :length], self._projection[:length], lower=True,
                                             trans="T", check_finite=False)


def band_limited(x: np.ndarray, fs: float, band: tuple[float, float]) -> np.ndarray:
    """x with its spectrum outside ``band`` (Hz) set to zero (zero phase, on a DFT of twice its length)."""
    n = 1 << int(np.ceil(np.log2(2 * x.size)))
    X = np.fft.rfft(x, n)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    X[(f < band[0]) | (f > band[1])] = 0.0
    return np.fft.irfft(X, n)[: x.size]


def fir_estimate(u: np.ndarray, y: np.ndarray, fs: float, length: int, start: int | None = None) -> FirEstimate:
    """Least-squares FIR of ``length`` taps from input ``u`` and ear signal ``y`` of one recording, fitted on the
    ear samples from ``start`` on (module docstring), with the residuals of its nested fits (``FirEstimate``):
    of every shorter FIR, and (on demand) with its first d taps held at zero.

    The samples before ``start`` (a noise recording's transient) serve as the input's history, so no ear sample
    is predicted from inputs that were not recorded; ``start`` defaults to ``2 length - 1``, the least the exact
    normal equations need (below). The normal equations
    are solved exactly (the covariance method): R_ij = sum_{t >= start} u[t - i] u[t - j] is the Toeplitz matrix
    of the lag products over t >= start less what the rows' shifted ranges leave out at the end and add at the
    start, O(length^2) from the lag products of the last and the first ``length`` samples. A Toeplitz
    approximation of R (the windowed method) is cheaper but inconsistent with the cross-correlation by
    O(length / N) where the low-passed input makes R ill-conditioned: 1.21x the floor instead of 1.02x on the
    HD 600's 2048 taps.

    The nested fits come from one Cholesky factor R = L L^T (the order-recursive least squares of Levinson's
    kind): with v = L^-1 c, the fit of the first l taps leaves y'y - sum_{k < l} v_k^2. Holding the first d taps
    at zero raises the residual by g_d^T [(R^-1)_dd]^-1 g_d (the leading d x d block of R^-1); with the thin QR
    L^-1 [e_1 .. e_m] = Q T those blocks are T_d^T T_d, and the rises for every d <= m are the running sums of
    the squares of w = T^-T g_m, O(length^2 m).
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
    # R[i, i + d] = r_d - sum_{s = N - i}^{N - 1} u[s] u[s - d] + sum_{s = start - i}^{start - 1} u[s] u[s - d],
    # written one diagonal d at a time (both sides: R is symmetric), the sums running back from ``start`` and from
    # the end: no array but R itself of length^2 (134 MB at 4096 taps).
    head = u[start - 2 * length + 1: start][::-1]
    tail = u[u.size - 2 * length + 1:][::-1]
    R = np.empty((length, length))
    flat = R.reshape(-1)
    for d in range(length):
        diagonal = np.empty(length - d)
        diagonal[0] = r[d]
        reach = length - d - 1
        np.cumsum(head[:reach] * head[d: d + reach] - tail[:reach] * tail[d: d + reach], out=diagonal[1:])
        diagonal[1:] += r[d]
        flat[d:: length + 1][: length - d] = diagonal
        flat[d * length:: length + 1][: length - d] = diagonal
    # A loading of 1e-9 of the input power keeps the factorisation regular where the low-passed input has no power
    # (far above its cut-off): a tap error of 1e-9 of the response, far below any output noise.
    R[np.diag_indices(length)] *= 1.0 + 1e-9
    factor = scipy.linalg.cholesky(R, lower=True, overwrite_a=True, check_finite=False)
    v = scipy.linalg.solve_triangular(factor, c, lower=True, check_finite=False)
    g = scipy.linalg.solve_triangular(factor, v, lower=True, trans="T", check_finite=False)
    # Residuals of the nested fits by the normal equations: y'y - sum_{k < l} v_k^2 over the fitted samples.
    energy = float(np.dot(y[start:], y[start:]))
    residual = np.maximum(energy - np.concatenate(([0.0], np.cumsum(v**2))), 0.0)
    # The input's spectral density per sample, Phi_u(w) = sum_k r_k e^{-jwk} / n, on 0..pi from its correlation.
    symmetric = np.concatenate((r, np.zeros(1), r[:0:-1])) / n
    psd = np.maximum(np.fft.rfft(symmetric).real, 1e-300)
    return FirEstimate(g, fs, float(residual[-1]) / n, n, psd, residual, factor, v)


@dataclass
class FrequencyLimitedTruncation:
    """Every order's frequency-limited balanced truncation of one FIR (module docstring).

    ``hankel_singular_values``: the frequency-limited Hankel singular values, largest first;
    ``system(n)`` the stable order-n model (A, B, C, D) and the number of poles it reflected; ``realisation(n)``
    the same, balanced where poles were reflected; ``response(n, z)`` its frequency response at the points z.
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

    def system(self, n: int) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], int]:
        """The order-n projection of the shift register, its poles outside the unit circle reflected into it
        (p -> 1 / conj(p): the same magnitude response up to a constant per pole) and then its numerator fitted
        again by least squares to the FIR's response in band (``subspace.fit_b_d``); and how many it reflected."""
        system = self._projected(n)
        poles = np.linalg.eigvals(system[0])
        outside = np.abs(poles) >= 1.0
        if outside.any():
            return self._reflected(poles), int(outside.sum())
        return system, 0

    def realisation(self, n: int) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], int]:
        system, reflected = self.system(n)
        return (lti.balanced_realisation(*system) if reflected else system), reflected

    def response(self, n: int, z: np.ndarray) -> np.ndarray:
        """The frequency response of ``system(n)`` at the points z (complex, usually e^{j omega})."""
        A, B, C, D = self._projected(n)
        poles, V = np.linalg.eig(A)
        if np.any(np.abs(poles) >= 1.0):
            return system_response(*self._reflected(poles), z)
        V_inv, _ = lti.modal_inverse(V)
        if V_inv is None:
            return system_response(A, B, C, D, z)
        return lti.pole_residue_response(poles, (C[0] @ V) * (V_inv @ B[:, 0]), D[0, 0], np.asarray(z).reshape(-1))

    def _projected(self, n: int):
        if not 1 <= n <= self.max_order:
            raise ValueError(f"order must lie in 1..{self.max_order}; found {n}")
        scale = 1.0 / np.sqrt(self.hankel_singular_values[:n])
        left = scale[:, None] * self._left[:n]          # n x L: projects the shift register's state
        right = self._right[:, :n] * scale[None, :]     # L x n
        # The down-shift applied to the right basis: (A_shift right)[i] = right[i - 1], zero in the first row.
        A = left[:, 1:] @ right[:-1]
        B = left[:, :1].copy()
        C = self.taps[None, 1:] @ right
        D = np.array([[self.taps[0]]])
        return A, B, C, D

    def _reflected(self, poles: np.ndarray):
        """A real block-diagonal realisation of the reflected poles and the numerator fitted again (``system``)."""
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
        return A, B, C, D


def system_response(A, B, C, D, z: np.ndarray) -> np.ndarray:
    """G(z) = C (zI - A)^-1 B + D at the points z, for systems of hundreds of states: by the modal form where its
    eigenvectors are well conditioned (``lti.modal_form``), else by the complex Schur form A = Q T Q^H and one back
    substitution through T for all points at once (O(n^2) per point, where ``lti.frequency_response``'s batched
    dense solves take O(n^3) per point and memory of the points times n^2)."""
    z = np.asarray(z, dtype=complex).reshape(-1)
    modal = lti.modal_form(A, B, C, D)
    if modal.reliable:
        return lti.pole_residue_response(modal.poles, modal.residues, modal.d, z)
    A, B, C, D = lti.as_siso(A, B, C, D)
    T, Q = scipy.linalg.schur(A, output="complex")
    T = np.ascontiguousarray(T)
    b = Q.conj().T @ B[:, 0]
    c = C[0] @ Q
    n = T.shape[0]
    out = np.empty(z.size, dtype=complex)
    for start in range(0, z.size, _POINTS):
        points = z[start:start + _POINTS]
        # (z I - T) x = b from the last row up, every point a column of x.
        x = np.empty((n, points.size), dtype=complex)
        for i in range(n - 1, -1, -1):
            x[i] = (b[i] + T[i, i + 1:] @ x[i + 1:]) / (points - T[i, i])
        out[start:start + _POINTS] = c @ x + D
    return out


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
    if L > 2:
        vectors, ratios = scipy.signal.windows.dpss(L, half_bandwidth, Kmax=count, return_ratios=True)
    else:
        # scipy's dpss raises for two samples (its sign convention finds no sample of the odd window above its
        # threshold: a core of two taps behind a long delay, refitted on the seed's FB path through a quadratic
        # driver): the sinc kernel sin(2 pi W (i - j)) / (pi (i - j)), W = f_b / fs, decomposed directly.
        width = 2.0 * top / fs
        ratios, vectors = np.linalg.eigh(width * np.sinc(width * np.subtract.outer(np.arange(L), np.arange(L))))
        ratios, vectors = ratios[::-1], vectors[:, ::-1].T
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
