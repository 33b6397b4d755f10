"""The delay's onset reading (sysid.estimation.delay.onset): the onset of the band-limited impulse response."""

import numpy as np
import pytest

from sysid.core.model import Model
from sysid.estimation.delay import compensate_delay, delay_centimetres, estimate_latency
from sysid.estimation.spectra import estimate_spectra
from sysid.io.recordings import Recording
from sysid.random_plant import random_plant, random_session


def _noise_recording(model: Model, seconds: float, noise: float, seed: int) -> Recording:
    rng = np.random.default_rng(seed)
    u = 0.1 * rng.standard_normal(int(seconds * model.fs))
    return Recording(u, model.simulate(u) + noise * rng.standard_normal(u.size), model.fs)


class TestEstimateLatency:
    @pytest.mark.parametrize("delay", [0, 1, 7, 40, 150])
    def test_pure_delay_of_a_one_pole_path(self, delay):
        # y[t] = 0.5 y[t-1] + u[t-1-delay]: the impulse response starts at sample delay + 1.
        model = Model(path="fb", fs=44100.0, A=[[0.5]], B=[[1.0]], C=[[1.0]], D=[[0.0]], delay=delay)
        estimate = estimate_latency(estimate_spectra(_noise_recording(model, 3.0, 1e-4, delay)))
        assert delay - 4 <= estimate.samples <= delay

    @pytest.mark.parametrize("seed", range(6))
    def test_random_helmets_short_by_at_most_four_samples_never_long(self, seed):
        rp = random_plant(seed)
        session = random_session(seed, noise_duration=6.0, sweep_duration=0.5)
        estimate = estimate_latency(estimate_spectra(session.noise.trimmed(3.0)))
        # Never long (the core would have to be non-causal); short by the kernel's lead plus one.
        assert rp.delay - 4 <= estimate.samples <= rp.delay

    def test_centimetres(self):
        assert delay_centimetres(1, 44100.0) == pytest.approx(0.778, abs=1e-3)
        model = Model(path="fb", fs=48000.0, A=[[0.2]], B=[[1.0]], C=[[1.0]], D=[[0.0]], delay=12)
        estimate = estimate_latency(estimate_spectra(_noise_recording(model, 2.0, 1e-4, 3)))
        assert estimate.centimetres == pytest.approx(100 * 343.0 * estimate.samples / 48000.0)
        assert estimate.to_dict()["samples"] == estimate.samples


def test_compensate_delay_aligns_the_ear_signal():
    u = np.arange(10.0)
    recording = Recording(u, np.concatenate(([0.0, 0.0, 0.0], u[:7])), 1000.0)
    shifted = compensate_delay(recording, 3)
    np.testing.assert_array_equal(shifted.u, shifted.y)
    assert compensate_delay(recording, 0) is recording
    # A negative shift delays the ear signal: 2 of the 3 samples taken out come back, 2 samples shorter.
    back = compensate_delay(shifted, -2)
    assert back.u.size == back.y.size == 5
    np.testing.assert_array_equal(back.y[2:], back.u[:3])
