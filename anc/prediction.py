"""Predicted attenuation: per third-octave band, overall dB(A), and the coherence bound.

Ear power spectral density without control: Phi_dd. With the controller (``ear_psd``),
writing d = H x + u (``anc.disturbance``) and G = z^-L S_model:

.. math::
    \\Phi_{ee} = |1 + G Q|^2 \\, \\Phi_{uu} + \\Phi_{xx} \\, |G W + (1 + G Q) H|^2

(Q = 0 or W = 0 for a filter that is off; without a reference Phi_uu = Phi_dd). The
attenuation of a band is 10 log10 (integral of Phi_dd / integral of Phi_ee) over the band
(positive = quieter), the integrals over linear frequency (a band's power, as a third-octave
filter or a spectrum's bins measure it) by the trapezoid rule on ``POINTS_PER_BAND`` log-spaced
frequencies per band (``band_weights``). Summing the log-spaced points unweighted would integrate
over log frequency instead, weighting a band's low edge 1.26 times its high edge: with a notch
inside the band that put random pair 7/1012's 50 Hz band 0.8 dB shallower than its power integral
(22.4 against 23.2 dB with the true paths; the closed loop measured 23.9).
Overall dB(A): the same ratio with the IEC 61672-1 A-weighting over 20 Hz - 10 kHz.
Coherence bound: the most any feed-forward filter can remove, 10 log10(Phi_dd / Phi_uu)
= -10 log10(1 - coh^2).
"""

from __future__ import annotations

import numpy as np

from sysid.validation.compare import third_octave_bands

from .disturbance import Disturbance

__all__ = ["BANDS", "band_centres", "band_grid", "band_weights", "ear_psd", "band_attenuation", "overall_dba",
           "a_weighting", "coherence_bound", "drive_psd"]

BANDS = third_octave_bands(20.0, 2000.0)
POINTS_PER_BAND = 24
_trapezoid = getattr(np, "trapezoid", None) or np.trapz


def band_centres() -> list[float]:
    """Third-octave centres 20 Hz - 2 kHz (IEC 61260 base-10), Hz."""
    return [round(c, 1) for c, _, _ in BANDS]


def band_grid() -> np.ndarray:
    """(bands, POINTS_PER_BAND) log-spaced frequencies (Hz) inside each band."""
    return np.array([np.geomspace(lo, hi, POINTS_PER_BAND) for _, lo, hi in BANDS])


def band_weights() -> np.ndarray:
    """(bands, POINTS_PER_BAND) trapezoid weights (Hz) on ``band_grid()``: the sum over a row of weights
    times a PSD is the PSD's integral over the band in linear frequency, the band's power."""
    grid = band_grid()
    steps = np.diff(grid, axis=1) / 2.0
    weights = np.zeros_like(grid)
    weights[:, :-1] += steps
    weights[:, 1:] += steps
    return weights


def a_weighting(frequencies_hz) -> np.ndarray:
    """IEC 61672-1 A-weighting as a power ratio (0 dB at 1 kHz)."""
    f2 = np.asarray(frequencies_hz, dtype=float) ** 2
    ra = (12194.0**2 * f2**2) / ((f2 + 20.6**2) * np.sqrt((f2 + 107.7**2) * (f2 + 737.9**2)) * (f2 + 12194.0**2))
    return (ra * 10.0 ** (2.0 / 20.0)) ** 2


def ear_psd(disturbance: Disturbance, loop=None, secondary_w=None) -> np.ndarray:
    """Phi_ee on disturbance.frequencies_hz for loop = G Q and secondary_w = G W (arrays on that grid, or None)."""
    one_plus = 1.0 if loop is None else 1.0 + loop
    if not disturbance.has_reference:
        return np.abs(one_plus) ** 2 * disturbance.ear_psd
    gw = 0.0 if secondary_w is None else secondary_w
    H = disturbance.coherent_response()
    return (np.abs(one_plus) ** 2 * disturbance.incoherent_psd()
            + disturbance.reference_psd * np.abs(gw + one_plus * H) ** 2)


def drive_psd(disturbance: Disturbance, q=None, w=None) -> np.ndarray:
    """Phi_yy of the drive on disturbance.frequencies_hz for Q and W (their responses on that grid, or None).

    With the internal model exact the runtime's d_hat is the ear disturbance d = n + H x (n incoherent with
    the chin, H the chin-coherent response), so the drive y = W x + Q d = (W + Q H) x + Q n."""
    q = 0.0 if q is None else q
    if not disturbance.has_reference:
        return np.abs(q) ** 2 * disturbance.ear_psd
    w = 0.0 if w is None else w
    return (np.abs(q) ** 2 * disturbance.incoherent_psd()
            + disturbance.reference_psd * np.abs(w + q * disturbance.coherent_response()) ** 2)


def _ratio_db(off: np.ndarray, on: np.ndarray) -> float:
    return float(10.0 * np.log10(max(np.sum(off), 1e-300) / max(np.sum(on), 1e-300)))


def band_attenuation(off: np.ndarray, on: np.ndarray) -> list[float]:
    """Per-band attenuation (dB) from PSDs on ``band_grid()`` (same shape: bands x points), each band's
    power integrated over linear frequency (``band_weights``)."""
    weights = band_weights()
    return [_ratio_db(w * a, w * b) for w, a, b in zip(weights, off, on)]


def overall_dba(frequencies_hz: np.ndarray, off: np.ndarray, on: np.ndarray) -> float:
    """A-weighted overall attenuation (dB) from PSDs on a grid (trapezoidal integration)."""
    weight = a_weighting(frequencies_hz)
    return float(10.0 * np.log10(_trapezoid(weight * off, frequencies_hz) / max(_trapezoid(weight * on, frequencies_hz), 1e-300)))


def coherence_bound(disturbance: Disturbance) -> list[float]:
    """Per-band -10 log10(1 - coh^2) (dB); needs a reference (disturbance on ``band_grid()``)."""
    shape = band_grid().shape
    return band_attenuation(disturbance.ear_psd.reshape(shape), disturbance.incoherent_psd().reshape(shape))
