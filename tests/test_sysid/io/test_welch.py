"""sysid.io.welch: cross and auto spectra from a read(start, stop) callable, against their definitions."""

import numpy as np
import pytest

from sysid.core.errors import IdentificationError
from sysid.estimation.spectra import estimate_spectra
from sysid.io.recordings import Recording
from sysid.io.welch import Spectra, response, streamed_spectra


def _reference_spectra(u, y, fs, estimator, nperseg):
    """(s_uu, s_yu, s_yy, segments) by their definitions: scipy.signal's welch and csd (Hann, 50 % overlap,
    one-sided, scaling "spectrum") for h1; the averaged segment DFTs of seed eqs. 3.2-3.3 for seed-average."""
    import scipy.signal

    u, y = u - u.mean(), y - y.mean()
    segments = u.size // nperseg
    if estimator == "seed-average":
        U = np.fft.rfft(u[:segments * nperseg].reshape(segments, nperseg), axis=1).mean(axis=0) / nperseg
        Y = np.fft.rfft(y[:segments * nperseg].reshape(segments, nperseg), axis=1).mean(axis=0) / nperseg
        return np.abs(U) ** 2, Y * np.conj(U), np.abs(Y) ** 2, segments
    options = dict(fs=fs, window="hann", nperseg=nperseg, noverlap=nperseg // 2, detrend=False, scaling="spectrum")
    return (scipy.signal.welch(u, **options)[1], scipy.signal.csd(u, y, **options)[1], scipy.signal.welch(y, **options)[1],
            2 * segments - 1)


class TestStreamedSpectra:
    @pytest.mark.parametrize("estimator", ["h1", "seed-average"])
    @pytest.mark.parametrize("length, nperseg", [(44100, 2205), (30011, 2000), (2205, 2205)])
    def test_equals_definition_in_memory_and_streamed(self, length, nperseg, estimator):
        rng = np.random.default_rng(length)
        u = rng.standard_normal(length) * 0.1 + 0.01
        y = np.convolve(u, [0.5, -0.2, 0.1])[:length] + 1e-3 * rng.standard_normal(length)
        *reference, segments = _reference_spectra(u, y, 44100.0, estimator, nperseg)
        in_memory = estimate_spectra(Recording(u, y, 44100.0), estimator, nperseg)
        streamed = streamed_spectra(lambda a, b: (u[a:b], y[a:b]), length, 44100.0, nperseg, segments_per_block=3,
                                    estimator=estimator)
        for estimate in (in_memory, streamed):
            assert estimate.estimator == estimator
            assert estimate.segments == segments
            for name, expected in zip(("s_uu", "s_yu", "s_yy"), reference):
                np.testing.assert_allclose(getattr(estimate, name), expected, rtol=1e-9,
                                           atol=1e-12 * np.max(np.abs(expected)))

    def test_a_recording_shorter_than_a_segment_is_rejected(self):
        with pytest.raises(IdentificationError, match="tiny.wav: 0.00227 s after the transient is shorter than one "
                                                      "averaging segment of 0.05 s"):
            streamed_spectra(lambda a, b: (np.ones(b - a), np.ones(b - a)), 100, 44100.0, 2205, "tiny.wav")

    def test_an_unknown_estimator_is_rejected(self):
        with pytest.raises(IdentificationError, match="estimator must be one of h1, seed-average; found 'h3'"):
            streamed_spectra(lambda a, b: (np.ones(b - a), np.ones(b - a)), 4410, 44100.0, estimator="h3")


class TestResponse:
    def test_h1_h2_and_coherence_of_known_spectra_inside_the_band(self):
        # s_uu = 2, s_yu = 1 + j, s_yy = 1: H1 = (1 + j)/2, H2 = 1/(1 - j) = (1 + j)/2, coherence |1 + j|^2 / 2 = 1.
        n = 9
        spectra = Spectra(1600.0, 16, np.full(n, 2.0), np.full(n, 1 + 1j), np.ones(n), "h1", 1)
        frf = response(spectra, (200.0, 400.0))
        np.testing.assert_array_equal(frf.frequencies, [200.0, 300.0, 400.0])
        np.testing.assert_allclose(frf.g, 0.5 + 0.5j, rtol=1e-15)
        np.testing.assert_allclose(frf.h2, 0.5 + 0.5j, rtol=1e-15)
        np.testing.assert_allclose(frf.coherence, 1.0, rtol=1e-15)

    def test_a_bin_without_input_has_no_coherence(self):
        spectra = Spectra(1600.0, 16, np.zeros(9), np.zeros(9, dtype=complex), np.ones(9), "h1", 1)
        assert np.all(response(spectra, (0.0, 800.0)).coherence == 0.0)
