"""The long route (sysid.estimation.long_route) on a short session through the FABIAN HRIR (sysid/core/data,
Brinkmann et al., TU Berlin, CC BY 4.0)."""

import numpy as np
import pytest

from sysid.core.measured import measured_response
from sysid.estimation.long_route import fir_rms, fir_length, long_estimate
from sysid.estimation.long_response import fir_estimate
from sysid.identify import IdentificationOptions
from sysid.simulate import measured_session
from sysid.validation.sweeps import noise_floor, rms_from_responses, sweep_spectrum

SHORT = dict(noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)


@pytest.fixture(scope="module")
def fabian():
    session = measured_session("fabian_left_az60", **SHORT)
    return session, [sweep_spectrum(s) for s in session.sweeps], noise_floor(*session.sweeps)


def test_the_fir_validates_exactly_at_the_sweeps_bins(fabian):
    _, spectra, _ = fabian
    taps = measured_response("fabian_left_az60").taps
    responses = [np.polynomial.polynomial.polyval(np.exp(-2j * np.pi * s.frequencies / s.fs), taps) for s in spectra]
    assert fir_rms(taps, spectra) == pytest.approx(rms_from_responses(spectra, responses), rel=1e-9)


def test_the_length_is_what_the_response_needs_above_its_noise(fabian):
    session, spectra, floor = fabian
    noise = session.noise
    estimate = fir_estimate(noise.u, noise.y, noise.fs, 512, int(3.0 * noise.fs))
    length, tried = fir_length(estimate, spectra, floor)
    # The HRIR's 256 taps decay below the noise well before their end; 512 taps hold it with room.
    assert 40 < length < 256
    assert tried[length] ** 2 <= min(tried.values()) ** 2 + 0.01 * floor**2 + 1e-30
    shorter = max(n for n in tried if n < length)
    assert tried[shorter] ** 2 > min(tried.values()) ** 2 + 0.01 * floor**2


def test_the_estimate_holds_the_hrir_and_its_ladder_reaches_the_floor(fabian):
    session, _, floor = fabian
    options = IdentificationOptions()
    estimate = long_estimate(session.noise, session.sweeps, floor, options.band, options.validation_band,
                             options.transient_s, options.max_delay)
    assert estimate.held and estimate.curve is not None
    assert estimate.delay.taps <= 11 and estimate.line == max(estimate.delay.taps - 1, 0)
    n = estimate.curve.lowest_at_floor()
    assert estimate.curve.ratio(n) < 1.2
