"""Lines the input does not drive: found, fitted beside the plant's response, told from modes."""

import numpy as np
import pytest
import scipy.signal

from sysid.io.lines import driven, find_lines, fit_sinusoids, response_lines, without_lines
from sysid.io.recordings import Recording


def _hum(n: int, fs: float, phase: float = 0.7) -> np.ndarray:
    t = np.arange(n) / fs
    return sum(np.sqrt(2) * 1e-3 / k * np.sin(2 * np.pi * 50.0 * k * t + k * phase) for k in (1, 2, 3))


def test_a_hum_is_fitted_beside_a_sweeps_response(sessions):
    # The sweep's response passes through 50, 100 and 150 Hz far above the hum: a plain least-squares
    # fit of the lines takes part of it for the hum, the fit beside the response (local polynomial)
    # leaves of the hum about what the 16-bit quantisation of the two recordings does.
    sweep = sessions["fb"].sweeps[0]
    hum = _hum(sweep.y.size, sweep.fs)
    hummed = Recording(sweep.u, sweep.y + hum, sweep.fs)
    lines = [50.0, 100.0, 150.0]
    beside = np.std(hum - response_lines(hummed.u, hummed.y, lines, sweep.fs))
    plain = np.std(hum - fit_sinusoids(hummed.y, lines, sweep.fs))
    assert beside < 0.03 * np.std(hum) and plain > 3 * beside
    assert np.std(without_lines(hummed, lines).y - sweep.y) == pytest.approx(beside)
    assert without_lines(sweep, []) is sweep


def test_a_mode_is_driven_and_a_line_is_not():
    # A residual holding a lightly damped mode the model lacks (130 Hz, Q 100) and a 60 Hz line: both
    # peak far above their neighbourhood where the input is flat, only the mode is coherent with it.
    rng = np.random.default_rng(4)
    fs, n = 48000.0, 5 * 48000
    u = rng.standard_normal(n)
    b, a = scipy.signal.iirpeak(130.0, 100.0, fs)
    t = np.arange(n) / fs
    x = 0.05 * scipy.signal.lfilter(b, a, u) + 2e-3 * np.sin(2 * np.pi * 60.0 * t) + 1e-4 * rng.standard_normal(n)
    peaks = [line[0] for line in find_lines(x, u, fs)]
    assert len(peaks) == 2 and peaks[0] == pytest.approx(60.0, abs=0.1) and peaks[1] == pytest.approx(130.0, abs=0.5)
    assert driven(x, u, fs, peaks) == [False, True]
    assert driven(x, u, fs, []) == []


@pytest.mark.parametrize("frequencies", [[50.0], [41.7, 83.4, 125.1], [50.0, 50.0]])
def test_the_blocked_fit_is_the_least_squares_fit(frequencies):
    # fit_sinusoids sums the normal equations block by block from rotated exponentials; the fit is the
    # plain least-squares fit on the whole regressor (coinciding lines included), with a mask too.
    from sysid.io.lines import FIT_BLOCK, line_regressor

    rng = np.random.default_rng(7)
    fs, n = 48000.0, 3 * FIT_BLOCK + 123
    t = np.arange(n) / fs
    x = 1e-3 * np.cos(2 * np.pi * 50.03 * t + 0.4) + 3e-4 * np.sin(2 * np.pi * 125.0 * t) + 1e-3 * rng.standard_normal(n)
    keep = rng.random(n) > 0.2
    for mask in (None, keep):
        regressor = line_regressor(n, frequencies, fs)
        rows = regressor if mask is None else regressor[mask]
        theta = np.linalg.lstsq(rows, x if mask is None else x[mask], rcond=None)[0]
        np.testing.assert_allclose(fit_sinusoids(x, frequencies, fs, keep=mask), regressor @ theta, rtol=0, atol=1e-12)
