"""Non-parametric frequency-response estimates from a noise recording (seed chapter 3).

Two estimators of the input/output spectra on the N-point grid f_n = n fs / N,
N = fs / f_min (2205 at 44.1 kHz for f_min = 20 Hz, seed section 3.1):

* ``seed-average`` (seed eqs. 3.2-3.3): the DFTs of the N_s non-overlapping segments
  are averaged first, U_av = mean_i U_i, Y_av = mean_i Y_i, and G_E = Y_av / U_av.
  Segment transients telescope so leakage cancels, but averaging the DFTs of
  independent noise segments averages the *signal* towards zero as fast as the
  noise: the output-noise error does not fall with N_s.
* ``h1`` (default): Welch averages of the cross and auto spectra (Hann window, 50 %
  overlap), H1 = S_yu / S_uu, H2 = S_yy / S_uy and the coherence
  gamma^2 = |S_yu|^2 / (S_uu S_yy). H1 is unbiased for output noise and biased low
  by 1 / (1 + S_nn/S_uu) for input noise; H2 is biased high; H1 != H2 flags
  errors-in-variables.

Cross-spectrum convention: S_yu(f) = E[Y(f) conj(U(f))] (Ljung's Phi_yu), which is
what ``scipy.signal.csd(u, y)`` returns (it conjugates its *first* argument).

Smoothing (seed section 3.2, corrected): Blackman-Tukey, i.e. the spectra's inverse
DFT (correlation estimates R(k)) times Ljung's Parzen lag window of width gamma,
transformed back:
    w(k) = 1 - 6 (k/g)^2 + 6 |k/g|^3   for |k| <= g/2,
           2 (1 - |k|/g)^3              for g/2 < |k| <= g,
           0                            otherwise
(Ljung, System Identification, 2nd ed., table 6.1). The seed's printed frequency
window has numerator and denominator swapped; it is not used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal
from numpy.lib.stride_tricks import sliding_window_view

from ..core.errors import IdentificationError
from ..io.recordings import Recording, RecordingFile

__all__ = [
    "ESTIMATORS",
    "Spectra",
    "FrequencyResponse",
    "segment_length",
    "estimate_spectra",
    "streamed_spectra",
    "parzen_lag_window",
    "smooth_spectra",
    "smoothed_response",
    "smoothed_responses",
    "response",
]

ESTIMATORS = ("h1", "seed-average")


def segment_length(fs: float, f_min: float = 20.0) -> int:
    """N = fs / f_min samples, so that the DFT grid step equals f_min (seed section 3.1)."""
    return int(round(fs / f_min))


@dataclass
class Spectra:
    """One-sided spectra on the grid f = n fs / N, n = 0..N//2 (units FS^2 per bin)."""

    fs: float
    nperseg: int
    s_uu: np.ndarray
    s_yu: np.ndarray
    s_yy: np.ndarray
    estimator: str
    segments: int

    @property
    def frequencies(self) -> np.ndarray:
        return np.arange(self.s_uu.size) * self.fs / self.nperseg


@dataclass
class FrequencyResponse:
    """FRF samples at ``frequencies`` (Hz): H1 estimate ``g``, H2 and coherence (squared)."""

    frequencies: np.ndarray
    g: np.ndarray
    h2: np.ndarray
    coherence: np.ndarray


def estimate_spectra(noise: Recording | RecordingFile, estimator: str = "h1", nperseg: int | None = None) -> Spectra:
    """Input/output spectra of a noise recording (transient already removed) by ``estimator``.

    A ``RecordingFile`` (read from disk in blocks) goes through ``streamed_spectra``,
    which gives the same spectra to rounding in bounded memory.
    """
    if estimator not in ESTIMATORS:
        raise IdentificationError(f"estimator must be one of {', '.join(ESTIMATORS)}; found {estimator!r}")
    if isinstance(noise, RecordingFile):
        return streamed_spectra(noise.read, noise.length, noise.fs, nperseg, noise.path, estimator=estimator)
    # In memory too, by the same blocks: each segment's two DFTs once, where scipy.signal's welch (u),
    # welch (y) and csd (u, y) took four DFTs of every segment between them, one segment at a time.
    return streamed_spectra(lambda start, stop: (noise.u[start:stop], noise.y[start:stop]), noise.u.size, noise.fs,
                            nperseg, noise.path, estimator=estimator)


def streamed_spectra(read, length: int, fs: float, nperseg: int | None = None, name: str = "<stream>",
                     segments_per_block: int = 256, estimator: str = "h1") -> Spectra:
    """The spectra of ``estimate_spectra`` computed block by block, in bounded memory.

    ``read(start, stop)`` returns the (u, y) samples start..stop-1 (full-scale units) of a
    recording of ``length`` samples (transient already removed). Two passes: the channel
    means, then the same segments as the in-memory estimator, ``segments_per_block`` at a
    time, so memory is a few blocks of segments whatever the length. For h1 these are
    the Hann-windowed, 50 %-overlapping segments of ``scipy.signal.welch`` (starts 0,
    step = nperseg - nperseg // 2, no padding); for seed-average the non-overlapping
    rectangular ones. The result equals ``estimate_spectra`` on the samples in memory to rounding.
    """
    if estimator not in ESTIMATORS:
        raise IdentificationError(f"estimator must be one of {', '.join(ESTIMATORS)}; found {estimator!r}")
    nperseg = nperseg or segment_length(fs)
    if length // nperseg < 1:
        raise IdentificationError(f"{name}: {length / fs:.3g} s after the transient is shorter than one "
                                  f"averaging segment of {nperseg / fs:.3g} s")
    step = nperseg - nperseg // 2
    sums = np.zeros(2)
    for start in range(0, length, step * segments_per_block):
        u, y = read(start, min(start + step * segments_per_block, length))
        sums += (np.sum(u), np.sum(y))
    mean_u, mean_y = sums / length
    if estimator == "seed-average":
        return _streamed_seed_average(read, length, fs, nperseg, mean_u, mean_y, segments_per_block)
    count = (length - nperseg) // step + 1
    window = scipy.signal.get_window("hann", nperseg)
    s_uu = np.zeros(nperseg // 2 + 1)
    s_yy = np.zeros(nperseg // 2 + 1)
    s_yu = np.zeros(nperseg // 2 + 1, dtype=complex)
    for first in range(0, count, segments_per_block):
        last = min(first + segments_per_block, count)
        u, y = read(first * step, (last - 1) * step + nperseg)
        U = np.fft.rfft((sliding_window_view(u, nperseg)[::step] - mean_u) * window, axis=1)
        Y = np.fft.rfft((sliding_window_view(y, nperseg)[::step] - mean_y) * window, axis=1)
        s_uu += np.sum(np.abs(U) ** 2, axis=0)
        s_yy += np.sum(np.abs(Y) ** 2, axis=0)
        s_yu += np.sum(Y * np.conj(U), axis=0)
    # scaling="spectrum": divide by (sum w)^2; one-sided: double every bin but DC (and Nyquist for even N).
    scale = np.full(nperseg // 2 + 1, 2.0) / (count * window.sum() ** 2)
    scale[0] /= 2
    if nperseg % 2 == 0:
        scale[-1] /= 2
    return Spectra(fs, nperseg, s_uu * scale, s_yu * scale, s_yy * scale, "h1", 2 * (length // nperseg) - 1)


def _streamed_seed_average(read, length: int, fs: float, nperseg: int, mean_u: float, mean_y: float,
                           segments_per_block: int) -> Spectra:
    """The seed's averaged segment DFTs (eqs. 3.2-3.3) of ``streamed_spectra``, block by block."""
    segments = length // nperseg
    U = np.zeros(nperseg // 2 + 1, dtype=complex)
    Y = np.zeros(nperseg // 2 + 1, dtype=complex)
    for first in range(0, segments, segments_per_block):
        last = min(first + segments_per_block, segments)
        u, y = read(first * nperseg, last * nperseg)
        U += np.fft.rfft((u - mean_u).reshape(last - first, nperseg), axis=1).sum(axis=0)
        Y += np.fft.rfft((y - mean_y).reshape(last - first, nperseg), axis=1).sum(axis=0)
    U /= segments * nperseg
    Y /= segments * nperseg
    return Spectra(fs, nperseg, np.abs(U) ** 2, Y * np.conj(U), np.abs(Y) ** 2, "seed-average", segments)


def response(spectra: Spectra, band: tuple[float, float]) -> FrequencyResponse:
    """H1, H2 and squared coherence at the grid frequencies inside band (Hz, inclusive)."""
    f = spectra.frequencies
    inside = (f >= band[0]) & (f <= band[1])
    s_uu, s_yu, s_yy = spectra.s_uu[inside], spectra.s_yu[inside], spectra.s_yy[inside]
    with np.errstate(divide="ignore", invalid="ignore"):
        h1 = s_yu / s_uu
        h2 = s_yy / np.conj(s_yu)
        coherence = np.abs(s_yu) ** 2 / (s_uu * s_yy)
    return FrequencyResponse(f[inside], h1, h2, np.clip(np.nan_to_num(coherence), 0.0, 1.0))


def parzen_lag_window(gamma: int, n: int) -> np.ndarray:
    """Ljung's Parzen lag window w_gamma(k) for the circular lags k = 0..n-1 (k and n-k alike)."""
    if gamma < 1:
        raise IdentificationError(f"smoothing width gamma must be at least 1; found {gamma}")
    k = np.minimum(np.arange(n), n - np.arange(n)) / gamma
    return np.where(k <= 0.5, 1 - 6 * k**2 + 6 * k**3, np.where(k <= 1.0, 2 * (1 - k) ** 3, 0.0))


def smooth_spectra(spectra: Spectra, gamma: int) -> Spectra:
    """Blackman-Tukey smoothing of all three spectra with the Parzen lag window of width gamma."""
    s_uu, s_yu, s_yy = _smoothed(spectra, [gamma])
    return Spectra(spectra.fs, spectra.nperseg, s_uu[0], s_yu[0], s_yy[0], spectra.estimator, spectra.segments)


def _smoothed(spectra: Spectra, gammas) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s_uu, s_yu, s_yy) smoothed at each width in ``gammas`` (rows): each spectrum's correlation
    estimate (inverse DFT) once, times every width's lag window, transformed back in one call."""
    n = spectra.nperseg
    if max(gammas) > n // 2:
        raise IdentificationError(f"smoothing width gamma={max(gammas)} exceeds half the segment length ({n // 2} samples)")
    windows = np.array([parzen_lag_window(int(gamma), n) for gamma in gammas])

    def smooth(s):
        return np.fft.rfft(np.fft.irfft(s, n)[None, :] * windows, axis=1)

    return smooth(spectra.s_uu).real, smooth(spectra.s_yu), smooth(spectra.s_yy).real


def smoothed_responses(spectra: Spectra, gammas, band: tuple[float, float]) -> list[FrequencyResponse]:
    """``smoothed_response`` at each width in ``gammas`` (the seed's grid smooths at a hundred)."""
    s_uu, s_yu, s_yy = _smoothed(spectra, gammas)
    return [response(Spectra(spectra.fs, spectra.nperseg, s_uu[i], s_yu[i], s_yy[i], spectra.estimator, spectra.segments),
                     band) for i in range(len(gammas))]


def smoothed_response(spectra: Spectra, gamma: int, band: tuple[float, float]) -> FrequencyResponse:
    """The smoothed FRF G_smooth = Phi_yu / Phi_u (seed eq. 3.8) inside band."""
    return response(smooth_spectra(spectra, gamma), band)
