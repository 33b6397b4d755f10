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


def test_above_the_output_error_order_the_numerator_is_refitted_only_where_asked(fabian, monkeypatch):
    # Above LONG_OE_ORDER a truncation above what the data allow gets its numerator refitted (one linear step on the
    # block); long_model asks for none above the floor's order, which it falls back on (HD 600, orders (600,): 473
    # states, that step 42 of the call's 74 s for a model it dropped).
    import dataclasses

    from sysid.estimation import long_route
    from sysid.estimation.output_error import block_data

    session, _, floor = fabian
    options = IdentificationOptions()
    estimate = long_estimate(session.noise, session.sweeps, floor, options.band, options.validation_band,
                             options.transient_s, options.max_delay)
    # The HRIR's truncation holds 40 states: the bound lowered below them, as the HD 600's 473 are above it.
    monkeypatch.setattr(long_route, "LONG_OE_ORDER", 20)
    order = 30
    assert estimate.truncation.max_order >= order > long_route.LONG_OE_ORDER
    # A floor far below this session's: every truncation is above what the data allow.
    estimate = dataclasses.replace(estimate, lengths={n: 1e-3 * floor for n in estimate.lengths})
    block = block_data(session.noise.trimmed(options.transient_s), options.band, 1.0)
    refits = []
    refine = long_route.refine_output_error
    monkeypatch.setattr(long_route, "refine_output_error", lambda *a, **k: refits.append(k) or refine(*a, **k))
    held = long_route.refine_long(estimate, order, block, 1e-3 * floor, polish=False)
    assert not refits and held.refinement == "truncation" and held.order == order
    long_route.refine_long(estimate, order, block, 1e-3 * floor)
    assert [k["max_iterations"] for k in refits] == [1]
