"""anc.prediction: a band's power is the integral of the PSD over linear frequency."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from anc.prediction import BANDS, band_attenuation, band_centres, band_grid, band_weights

FS = 48000.0
FIFTY = band_centres().index(50.1)


def test_the_weights_integrate_a_linear_psd_exactly():
    lo, hi = np.array([b[1] for b in BANDS]), np.array([b[2] for b in BANDS])
    weights = band_weights()
    np.testing.assert_allclose(weights.sum(axis=1), hi - lo, rtol=1e-12)
    np.testing.assert_allclose((weights * band_grid()).sum(axis=1), (hi**2 - lo**2) / 2.0, rtol=1e-12)


def _dense_attenuation(b, a, lo, hi) -> float:
    """10 log10 of the band's width over the integral of |H|^2 across it, on 20001 linearly spaced points."""
    f = np.linspace(lo, hi, 20001)
    _, response = scipy.signal.freqz(b, a, worN=f, fs=FS)
    return float(10.0 * np.log10((hi - lo) / np.trapezoid(np.abs(response) ** 2, f)))


@pytest.mark.parametrize("notch_hz, quality", [(46.0, 5.0), (47.0, 3.0), (50.0, 2.0), (53.0, 3.0)])
def test_a_notch_inside_a_band_is_predicted_as_its_power_integral(notch_hz, quality):
    # A notch off the band's centre: summing the log-spaced points unweighted integrated over log
    # frequency, 0.1-0.4 dB off these (the low edge counted 1.26 times the high edge).
    b, a = scipy.signal.iirnotch(notch_hz, quality, FS)
    grid = band_grid()
    _, response = scipy.signal.freqz(b, a, worN=grid.reshape(-1), fs=FS)
    on = (np.abs(response) ** 2).reshape(grid.shape)
    predicted = band_attenuation(np.ones_like(on), on)[FIFTY]
    _, lo, hi = BANDS[FIFTY]
    assert predicted == pytest.approx(_dense_attenuation(b, a, lo, hi), abs=0.05)
