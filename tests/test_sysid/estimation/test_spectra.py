"""Spectral estimates: Parzen lag window, H1 vs the seed's averaging, smoothing."""

import numpy as np
import pytest
import scipy.signal

from sysid.core.errors import IdentificationError
from sysid.estimation.spectra import estimate_spectra, parzen_lag_window, response, segment_length, smoothed_response
from sysid.io.recordings import Recording


class TestParzenLagWindow:
    def test_values_at_the_breakpoints(self):
        w = parzen_lag_window(100, 2205)
        assert w[0] == 1.0
        assert w[50] == pytest.approx(0.25)  # 1 - 6/4 + 6/8
        assert w[100] == pytest.approx(0.0)
        assert np.all(w[101:2105] == 0.0)

    def test_symmetric_in_circular_lag_and_continuous(self):
        w = parzen_lag_window(64, 1000)
        np.testing.assert_allclose(w[1:], w[1:][::-1])
        assert np.max(np.abs(np.diff(w[:70]))) < 0.05

    def test_gamma_below_one_is_rejected(self):
        with pytest.raises(IdentificationError, match="gamma must be at least 1"):
            parzen_lag_window(0, 100)


def _session(rng, seconds, output_noise, b=(0.0, 0.5, 0.3), a=(1.0, -0.6, 0.2)):
    fs = 44100.0
    u = rng.standard_normal(int(seconds * fs))
    y = scipy.signal.lfilter(b, a, u) + output_noise * rng.standard_normal(u.size)
    return Recording(u, y, fs, "test"), b, a


def _true_response(b, a, f, fs=44100.0):
    return scipy.signal.freqz(b, a, worN=f, fs=fs)[1]


def test_segment_length_is_the_seeds():
    assert segment_length(44100.0) == 2205


def test_h1_is_exact_without_noise(rng):
    rec, b, a = _session(rng, 2.0, 0.0)
    frf = response(estimate_spectra(rec, "h1"), (20, 5000))
    g = _true_response(b, a, frf.frequencies)
    # Only the Hann window's leakage of the segment transient remains.
    assert np.median(np.abs(frf.g - g) / np.abs(g)) < 2e-3
    assert np.median(frf.coherence) > 0.999


def test_cross_spectrum_convention_gives_a_delay_negative_phase(rng):
    rec, _, _ = _session(rng, 2.0, 0.0, b=(0.0, 0.0, 0.0, 1.0), a=(1.0,))
    frf = response(estimate_spectra(rec, "h1"), (20, 5000))
    expected = np.exp(-2j * np.pi * frf.frequencies * 3 / 44100)
    assert np.max(np.abs(frf.g - expected)) < 0.05


def test_h1_error_falls_with_segments_and_seed_average_does_not(rng):
    """At high output noise, averaging spectra (H1) gains; averaging DFTs (seed) does not."""
    rec, b, a = _session(rng, 12.0, 1.0)
    errors = {"h1": [], "seed-average": []}
    for seconds in (1.0, 12.0):
        n = int(seconds * rec.fs)
        part = Recording(rec.u[:n], rec.y[:n], rec.fs, "part")
        for estimator in errors:
            frf = response(estimate_spectra(part, estimator), (20, 5000))
            g = _true_response(b, a, frf.frequencies)
            errors[estimator].append(np.median(np.abs(frf.g - g) / np.abs(g)))
    # 12x the data: H1's error falls by about sqrt(12) ~ 3.5; the seed's stays put.
    assert errors["h1"][1] < errors["h1"][0] / 2.5
    assert errors["seed-average"][1] > errors["seed-average"][0] / 1.5
    assert errors["h1"][1] < errors["seed-average"][1] / 5


def test_h2_above_h1_with_input_noise(rng):
    fs = 44100.0
    u = rng.standard_normal(int(4 * fs))
    y = scipy.signal.lfilter([0.0, 0.5], [1.0, -0.5], u)
    rec = Recording(u + 0.5 * rng.standard_normal(u.size), y, fs, "eiv")
    frf = response(estimate_spectra(rec, "h1"), (20, 5000))
    # Input SNR 6 dB: H1 is biased low by 1/(1 + 0.25) and H2 is unbiased.
    assert np.median(np.abs(frf.g) / np.abs(frf.h2)) == pytest.approx(0.8, abs=0.03)
    assert np.median(frf.coherence) == pytest.approx(0.8, abs=0.03)


def test_smoothing_trades_variance_for_bias(rng):
    rec, b, a = _session(rng, 4.0, 0.5)
    raw = response(estimate_spectra(rec, "h1"), (20, 5000))
    smooth = smoothed_response(estimate_spectra(rec, "h1"), 100, (20, 5000))
    g = _true_response(b, a, raw.frequencies)
    assert np.median(np.abs(smooth.g - g)) < np.median(np.abs(raw.g - g)) / 2


def test_recording_shorter_than_a_segment_is_rejected(rng):
    rec = Recording(rng.standard_normal(100), rng.standard_normal(100), 44100.0, "tiny.wav")
    with pytest.raises(IdentificationError, match="tiny.wav: .* shorter than one averaging segment"):
        estimate_spectra(rec)


def test_estimate_spectra_is_the_streamed_estimator_on_the_samples_in_memory(rng):
    # The averaging itself is sysid.io.welch's, tested against the definitions there (test_welch.py).
    from sysid.io.recordings import Recording
    from sysid.io.welch import streamed_spectra

    u = rng.standard_normal(30011) * 0.1
    y = np.convolve(u, [0.5, -0.2, 0.1])[:u.size] + 1e-3 * rng.standard_normal(u.size)
    for estimator in ("h1", "seed-average"):
        in_memory = estimate_spectra(Recording(u, y, 44100.0, "m"), estimator, 2000)
        streamed = streamed_spectra(lambda a, b: (u[a:b], y[a:b]), u.size, 44100.0, 2000, "m", estimator=estimator)
        assert (in_memory.estimator, in_memory.segments) == (streamed.estimator, streamed.segments)
        for name in ("s_uu", "s_yu", "s_yy"):
            np.testing.assert_array_equal(getattr(in_memory, name), getattr(streamed, name))
