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

Both averages are computed in ``sysid.io.welch`` from a ``read(start, stop)`` callable,
so a recording read from its file in blocks and one in memory give the same spectra;
``Spectra``, ``FrequencyResponse``, ``segment_length``, ``streamed_spectra``,
``response`` and ``ESTIMATORS`` are importable from here as well.

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

import numpy as np

from ..core.errors import IdentificationError
from ..io.recordings import Recording, RecordingFile
from ..io.welch import ESTIMATORS, FrequencyResponse, Spectra, response, segment_length, streamed_spectra

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
