"""The long route's delay (sysid.estimation.delay.fir): leading taps of the least-squares FIR the data cannot tell
from zero. The FABIAN HRIR ships in sysid/core/data (Brinkmann et al., TU Berlin, CC BY 4.0)."""

import numpy as np
import scipy.signal

from sysid.core.measured import measured_response
from sysid.estimation.delay.fir import fir_delay
from sysid.estimation.long_response import fir_estimate
from sysid.simulate import measured_session


def _estimate(h, noise=1e-3, samples=40_000, seed=0, taps=64):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(samples)
    y = scipy.signal.lfilter(h, 1.0, u) + noise * rng.standard_normal(samples)
    return fir_estimate(u, y, 44100.0, taps)


def test_zero_leading_taps_are_the_delay():
    h = np.r_[np.zeros(7), 1.0, -0.6, 0.3, -0.1]
    delay = fir_delay(_estimate(h))
    # The test errs short: at most the 7 zero taps, and not fewer than the significance allows for (a false
    # response of the zero taps at p = 1e-3 on each of them would have to accumulate).
    assert 5 <= delay.taps <= 7
    assert delay.samples == delay.taps - 1 and not delay.feedthrough


def test_a_slowly_rising_response_is_not_read_long():
    # A rise over several samples 40-20 dB below the peak: every tap the data resolve stays in the model.
    h = np.r_[np.zeros(4), 0.01, 0.03, 0.1, 0.4, 1.0, 0.5, -0.2]
    delay = fir_delay(_estimate(h, noise=1e-4))
    assert delay.taps == 4


def test_a_response_from_lag_zero_keeps_its_direct_term():
    delay = fir_delay(_estimate(np.r_[0.5, 1.0, 0.3]))
    assert delay.taps == 0 and delay.samples == 0 and delay.feedthrough


def test_the_fabian_hrir_keeps_its_resolved_rise():
    # Its peak at sample 11 rises over several samples; whatever the test reads, it reads no tap above 1e-2 of the
    # peak as delay (the old onset read it 4 samples short of its peak, erring into the rise).
    session = measured_session("fabian_left_az60", noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)
    taps = measured_response("fabian_left_az60").taps
    noise = session.noise
    estimate = fir_estimate(noise.u, noise.y, noise.fs, 256, int(3.0 * noise.fs))
    delay = fir_delay(estimate, 100)
    first = int(np.flatnonzero(np.abs(taps) > 1e-2 * np.abs(taps).max())[0])
    assert delay.taps <= first
    assert np.all(np.diff(delay.limit[1:]) > 0)
