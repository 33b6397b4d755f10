"""Least-squares FIR estimates and their frequency-limited balanced truncation (sysid.estimation.long_response).

The measured responses are those shipped in sysid/core/data (credits there): a headphone transfer function
(HD 600 on a KEMAR, Geier and Erbes, University of Rostock) and a dummy-head HRIR (FABIAN, Brinkmann et al.,
TU Berlin), both CC BY 4.0.
"""

import numpy as np
import pytest
import scipy.signal

from sysid.core.measured import measured_response
from sysid.estimation.long_response import band_limited, fir_estimate, frequency_limited_truncation
from sysid.simulate import measured_session
from sysid.validation.sweeps import noise_floor, rms_from_responses, sweep_spectrum
from sysid.core import lti

SHORT = dict(noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)
BAND = (0.0, 5000.0)


def _validation_ratio(system, sweeps) -> float:
    spectra = [sweep_spectrum(s) for s in sweeps]
    responses = [lti.frequency_response(*system, np.exp(2j * np.pi * s.frequencies / s.fs)) for s in spectra]
    return rms_from_responses(spectra, responses) / noise_floor(*sweeps)


class TestFirEstimate:
    def test_a_known_filter_is_recovered_from_white_noise(self):
        rng = np.random.default_rng(0)
        u = rng.standard_normal(100_000)
        h = np.array([0.0, 0.0, 1.0, 0.5, -0.2])
        y = scipy.signal.lfilter(h, 1.0, u) + 1e-3 * rng.standard_normal(u.size)
        estimate = fir_estimate(u, y, 44100.0, 8)
        # sigma / sqrt(N) = 3.2e-6 per tap: within 5 of them.
        assert estimate.noise_rms((0.0, 22050.0)) == pytest.approx(3.2e-6, rel=0.1)
        np.testing.assert_allclose(estimate.taps, np.r_[h, 0, 0, 0], atol=1.6e-5)

    def test_the_stated_noise_matches_the_error_in_band(self):
        # Low-passed input (as a session's noise recording): out of band the taps are noise amplified by the input's
        # roll-off, in band their error is what noise_rms states (sigma^2 R^-1 / N, band-limited).
        session = measured_session("hptf_hd600_left", **SHORT)
        noise = session.noise
        estimate = fir_estimate(noise.u, noise.y, noise.fs, 2048, int(3.0 * noise.fs))
        truth = np.concatenate((session.plant.taps, np.zeros(2048)))[:2048]
        error = band_limited(estimate.taps - truth, noise.fs, (20.0, 5000.0))
        actual = float(np.sqrt(np.mean(error**2)))
        assert 0.7 < estimate.noise_rms((20.0, 5000.0)) / actual < 1.4


class TestFrequencyLimitedTruncation:
    def test_every_order_is_stable_and_the_error_falls_to_the_floor(self):
        session = measured_session("fabian_left_az60", **SHORT)
        noise = session.noise
        taps = fir_estimate(noise.u, noise.y, noise.fs, 160, int(3.0 * noise.fs)).taps
        truncation = frequency_limited_truncation(taps, noise.fs, BAND)
        ratios = {}
        for n in (10, 20, 30):
            system, _ = truncation.realisation(n)
            assert np.max(np.abs(np.linalg.eigvals(system[0]))) < 1.0
            ratios[n] = _validation_ratio(system, session.sweeps)
        assert ratios[30] < 1.2 < ratios[10]
        assert np.all(np.diff(truncation.hankel_singular_values) <= 0)

    def test_reaches_the_floor_below_the_true_taps_own_balanced_truncation(self):
        # The HD 600 needs about 620 states by balanced truncation of its true taps (issue 25); truncated in the band
        # the data determine, the estimate reaches the floor at far fewer.
        session = measured_session("hptf_hd600_left", **SHORT)
        noise = session.noise
        taps = fir_estimate(noise.u, noise.y, noise.fs, 2048, int(3.0 * noise.fs)).taps
        truncation = frequency_limited_truncation(taps, noise.fs, BAND)
        system, _ = truncation.realisation(400)
        assert np.max(np.abs(np.linalg.eigvals(system[0]))) < 1.0
        assert _validation_ratio(system, session.sweeps) < 1.2

    def test_order_outside_the_range_is_refused(self):
        truncation = frequency_limited_truncation(np.r_[0.0, 1.0, 0.5, 0.25], 44100.0, BAND)
        with pytest.raises(ValueError, match="order must lie in"):
            truncation.realisation(truncation.max_order + 1)


def test_measured_responses_load_with_their_rate():
    plant = measured_response("fabian_left_az60")
    assert plant.length == 128 and plant.fs == 44100.0 and "CC BY 4.0" in plant.credit
    session = measured_session("fabian_left_az60", effects=["delay:10"], **SHORT)
    assert session.truth["plant"]["format"] == "helmet-anc/fir-plant@1"
    assert len(session.truth["plant"]["taps"]) == 138


@pytest.mark.parametrize("length", [2, 3])
def test_a_core_of_two_or_three_taps_is_truncated(length):
    # Two taps are a window scipy's dpss cannot give (IndexError); three it can, the same kernel either way.
    taps = np.array([0.0, 0.8, -0.3])[:length]
    truncation = frequency_limited_truncation(taps, 44100.0, (0.0, 5000.0))
    values = truncation.hankel_singular_values
    assert values.size >= 1 and np.all(np.isfinite(values)) and values[0] > 0
