"""The causal Wiener filter of any length on a dense FFT grid, by spectral factorisation.

Everything here works on the one-sided grid of a real N-point FFT (``FFTGrid``: bins
k fs / N, k = 0 .. N/2): a response on that grid is the DFT of an N-sample real impulse
response read circularly, times 0 .. N/2 - 1 causal and N/2 .. N - 1 the negative times.

* ``minimum_phase``: the minimum-phase factor L of a positive power spectrum, |L|^2 = Phi,
  by the real cepstrum (Kolmogorov 1939; Oppenheim & Schafer, "Discrete-Time Signal
  Processing", 3rd ed., sec. 13.8, eq. 13.96-13.98): the cepstrum of log |L| = log(Phi) / 2
  folded onto the non-negative times.
* ``causal_part``: [X]_+, the part of X at times >= 0.
* ``allpass_split``: G = G_ap G_mp with G_mp the minimum-phase factor of |G|^2 + floor
  (the floor keeps 1 / G_mp bounded where G is tiny or has zeros on the unit circle) and
  |G_ap| <= 1; G_ap carries the delay and the zeros outside the unit circle.
* ``causal_wiener``: the causal W minimising the weighted ear power from the reference

.. math::
    J(W) = \\sum_k V \\Phi_{xx} \\left( |T + G W|^2 + R |W|^2 \\right),

  with |Lambda|^2 = V Phi_xx (|G|^2 + R) (Lambda minimum phase) the solution is
  (Bode & Shannon, Proc. IRE 38, 1950; Kailath, Sayed & Hassibi, "Linear Estimation",
  2000, sec. 7.3)

.. math::
    W = -\\frac{1}{\\Lambda} \\left[ \\frac{V \\Phi_{xx} G^* T}{\\Lambda^*} \\right]_+ ,

  which for V = 1, R = 0 and |M|^2 = Phi_xx is design.md's W = -[G_ap^* T M]_+ / (G_mp M).
  Here T is the reference-to-ear response W has to cancel (H, or (1 + G Q) H with feedback
  Q), R >= 0 a penalty on W (the model's relative error s^2 |G|^2 and a floor), V > 0 a
  weight per frequency. J(W) - J(W_opt) = sum V Phi_xx (|G|^2 + R) |W - W_opt|^2 for every
  causal W (the projection theorem), so a filter fitted to W_opt in that weight (``anc.feedforward``)
  loses exactly its weighted distance.

The grid must be long against the slowest pole of the paths and of the factors (time
aliasing of the circular responses): ``FFTGrid.for_paths`` takes eight time constants of the
slowest pole, at least 2^15 and at most 2^19 points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FFTGrid", "minimum_phase", "causal_part", "allpass_split", "causal_wiener", "relative_floor"]

_MIN_POINTS = 2 ** 15
_MAX_POINTS = 2 ** 19
# Time constants of the slowest pole the grid holds (the circular responses decay by e^-8 over it).
_TIME_CONSTANTS = 8.0


@dataclass(frozen=True)
class FFTGrid:
    """One-sided grid of an ``points``-point real FFT at sample rate ``fs`` (Hz)."""

    fs: float
    points: int

    @classmethod
    def for_paths(cls, fs: float, *pole_sets) -> "FFTGrid":
        """A grid long enough for the slowest of the given poles (arrays of complex poles)."""
        radius = max([float(np.max(np.abs(p))) for p in pole_sets if np.size(p)] + [0.0])
        samples = _TIME_CONSTANTS / max(-np.log(min(radius, 1.0 - 1e-9)), 1e-12) if radius > 0 else 0.0
        points = _MIN_POINTS
        while points < samples and points < _MAX_POINTS:
            points *= 2
        return cls(float(fs), points)

    @property
    def frequencies_hz(self) -> np.ndarray:
        return np.fft.rfftfreq(self.points, 1.0 / self.fs)

    def impulse_response(self, response: np.ndarray) -> np.ndarray:
        """The N-sample circular impulse response of a response on this grid."""
        return np.fft.irfft(response, self.points)


def relative_floor(values: np.ndarray, fraction: float) -> np.ndarray:
    """values + fraction * max(values): a positive spectrum for the factorisation."""
    values = np.maximum(np.asarray(values, dtype=float), 0.0)
    peak = float(np.max(values)) if values.size else 0.0
    return values + fraction * (peak if peak > 0.0 else 1.0)


def minimum_phase(power: np.ndarray, points: int) -> np.ndarray:
    """L on the one-sided grid of a ``points``-point FFT with |L|^2 = power (positive) and L
    minimum phase: causal, with a causal stable inverse (module docstring)."""
    power = np.asarray(power, dtype=float)
    if power.shape != (points // 2 + 1,):
        raise ValueError(f"expected a spectrum of {points // 2 + 1} points; found {power.shape}")
    if not np.all(power > 0.0) or not np.all(np.isfinite(power)):
        raise ValueError("the spectrum to factor must be positive and finite at every point")
    cepstrum = np.fft.irfft(0.5 * np.log(power), points)
    # Fold the even cepstrum onto the causal times: c_0, 2 c_n (0 < n < N/2), c_{N/2}.
    folded = np.zeros(points)
    half = points // 2
    folded[0] = cepstrum[0]
    folded[1:half] = 2.0 * cepstrum[1:half]
    folded[half] = cepstrum[half]
    return np.exp(np.fft.rfft(folded))


def causal_part(response: np.ndarray, points: int) -> np.ndarray:
    """[X]_+: the response of the times 0 .. N/2 - 1 of X's circular impulse response."""
    impulse = np.fft.irfft(response, points)
    impulse[points // 2:] = 0.0
    return np.fft.rfft(impulse)


def allpass_split(response: np.ndarray, points: int, floor: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
    """(G_ap, G_mp) with G = G_ap G_mp on the grid: G_mp the minimum-phase factor of |G|^2 plus ``floor``
    times its peak, G_ap = G / G_mp (|G_ap| = 1 wherever |G|^2 is far above the floor)."""
    magnitude = relative_floor(np.abs(response) ** 2, floor)
    G_mp = minimum_phase(magnitude, points)
    return response / G_mp, G_mp


def causal_wiener(G: np.ndarray, T: np.ndarray, phi_xx: np.ndarray, points: int, effort: np.ndarray | float = 0.0,
                  weight: np.ndarray | float = 1.0) -> np.ndarray:
    """The causal W minimising J (module docstring) on the one-sided grid of a ``points``-point FFT.

    ``G``: secondary path z^-L S; ``T``: what W cancels; ``phi_xx``: reference PSD (positive);
    ``effort``: R; ``weight``: V. All on the grid. V Phi_xx (|G|^2 + R) must be positive.
    """
    spectrum = weight * phi_xx * (np.abs(G) ** 2 + effort)
    Lam = minimum_phase(spectrum, points)
    return -causal_part(weight * phi_xx * np.conj(G) * T / np.conj(Lam), points) / Lam
