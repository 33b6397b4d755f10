"""Cross and auto spectra of a stereo recording read through a ``read(start, stop)`` callable.

``streamed_spectra`` asks ``read`` for the (u, y) samples of one block of segments at a
time, so a ``RecordingFile`` read from its WAV file and a ``Recording`` in memory share
one estimator and its bits (``sysid.estimation.spectra.estimate_spectra`` gives it
either; the ear-channel check of ``sysid.io.ear_channel`` gives it stretches of a file).
Two averages on the N-point grid f_n = n fs / N (seed section 3.1):

* ``h1``: Welch's averaged periodograms of the cross and auto spectra (Hann window,
  50 % overlap; P. D. Welch, "The use of fast Fourier transform for the estimation of
  power spectra", IEEE Trans. Audio Electroacoust. 15(2), 1967, pp. 70-73);
* ``seed-average``: the seed's averaged segment DFTs (seed eqs. 3.2-3.3).

``response`` turns the spectra into H1 = S_yu / S_uu, H2 = S_yy / S_uy and the
magnitude-squared coherence gamma^2 = |S_yu|^2 / (S_uu S_yy). Cross-spectrum
convention: S_yu(f) = E[Y(f) conj(U(f))] (Ljung's Phi_yu), which is what
``scipy.signal.csd(u, y)`` returns (it conjugates its *first* argument).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal
from numpy.lib.stride_tricks import sliding_window_view

from ..core.errors import IdentificationError

__all__ = ["ESTIMATORS", "Spectra", "FrequencyResponse", "segment_length", "streamed_spectra", "response"]

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


def streamed_spectra(read, length: int, fs: float, nperseg: int | None = None, name: str = "<stream>",
                     segments_per_block: int = 256, estimator: str = "h1") -> Spectra:
    """The spectra of ``sysid.estimation.spectra.estimate_spectra`` computed block by block, in bounded memory.

    ``read(start, stop)`` returns the (u, y) samples start..stop-1 (full-scale units) of a
    recording of ``length`` samples (transient already removed). Two passes: the channel
    means, then the same segments as the in-memory estimator, ``segments_per_block`` at a
    time, so memory is a few blocks of segments whatever the length. For h1 these are
    the Hann-windowed, 50 %-overlapping segments of ``scipy.signal.welch`` (starts 0,
    step = nperseg - nperseg // 2, no padding); for seed-average the non-overlapping
    rectangular ones. The result equals the spectra by their definitions (scipy.signal's ``welch`` and
    ``csd``; seed eqs. 3.2-3.3) on the samples in memory to rounding.
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
