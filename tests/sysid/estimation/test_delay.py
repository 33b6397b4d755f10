"""Latency estimate (sysid.estimation.delay): the onset of the band-limited impulse response."""

import numpy as np
import pytest

from sysid.core import lti
from sysid.core.model import Model
from sysid.estimation.delay import (compensate_delay, decide_delay, delay_centimetres, estimate_latency, refine_delay,
                                    walk_delay, without_residual_lines)
from sysid.estimation.output_error import block_data, linear_cost, refine_output_error
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


BAND = (20.0, 5000.0)


def _behind_delay(seed: int, off_by: int):
    """(random plant ``seed``, its 2 s noise body with rp.delay + off_by samples taken out: short when
    off_by < 0, long when > 0)."""
    rp = random_plant(seed)
    session = random_session(seed, noise_duration=5.0, sweep_duration=0.5)
    return rp, compensate_delay(session.noise.trimmed(3.0), rp.delay + off_by)


def _with_spare_poles(rp, spare) -> np.ndarray:
    """A = the plant's poles and the spare ones, real block diagonal."""
    return lti.real_block_diagonal(np.concatenate([np.linalg.eigvals(rp.model.A), spare]))


class TestRefineDelay:
    @pytest.mark.parametrize("seed", [0, 3, 7, 12])
    def test_missing_samples_found_from_the_cost_at_the_model_poles(self, seed):
        # A core behind a delay 3 samples short: the true poles plus three spare poles near
        # z = 0 (which imitate z^-3). The fixed-pole cost stays flat up to the true delay and
        # rises after it; plants whose response starts smoothly may be read one sample long.
        rp, body = _behind_delay(seed, -3)
        extra, costs = refine_delay(_with_spare_poles(rp, [0.0, 0.02, -0.02]), body, BAND, 1.0)
        assert extra in (3, 4)
        assert costs.shape == (5,) and costs[3] <= costs.min() * 1.001

    @pytest.mark.parametrize("seed", [0, 3, 7, 12])
    def test_window_grows_while_the_cost_still_falls(self, seed):
        # 9 samples short with 3 spare poles: the cost falls up to j = 6 (beyond the first
        # window of 4), stays flat to 9 (or one or two more for smooth starts), then rises.
        rp, body = _behind_delay(seed, -9)
        extra, costs = refine_delay(_with_spare_poles(rp, [0.0, 0.02, -0.02]), body, BAND, 1.0)
        assert 9 <= extra <= 11
        assert costs.size == 13 and costs[0] > 1.5 * costs.min()

    @pytest.mark.parametrize("seed", [0, 3, 12])
    def test_a_delay_read_long_is_shortened(self, seed):
        # The true poles behind a delay 3 samples too long: the core cannot be causal, the
        # fixed-pole cost falls below the onset's delay, and the refitted costs find the true delay.
        rp, body = _behind_delay(seed, 3)
        extra, costs = refine_delay(rp.model.A, body, BAND, 1.0, delay=rp.delay + 3)
        assert extra == -3
        # Refitted at j = -4..0, lowest first; nothing above the onset's delay.
        assert costs.size == 9 and np.all(np.isfinite(costs[:5])) and np.all(np.isinf(costs[5:]))
        assert np.argmin(costs) == 1
        # Never below a total delay of zero: with 1 sample taken out, at most that one comes back.
        assert -1 <= refine_delay(rp.model.A, body, BAND, 1.0, delay=1)[0] <= 0
        assert refine_delay(rp.model.A, body, BAND, 1.0)[0] >= 0

    def test_a_delay_read_long_beyond_the_first_window_is_found(self):
        # 7 samples too long (modes that outlast the Welch segment raise the onset's threshold): the
        # window grows downwards while its first cost is the smallest, and the refitted costs decide.
        rp, body = _behind_delay(0, 7)
        extra, costs = refine_delay(rp.model.A, body, BAND, 1.0, delay=rp.delay + 7)
        assert extra == -7
        assert costs.size == 13 and np.argmin(costs) == 1

    def test_hum_is_taken_out_before_the_delay_is_judged(self):
        # An engine order (41.7 Hz and two harmonics) 80 times the sensor noise: no delay fits it, and
        # left in the cost it read this delay 7 samples long (j = +4). Fitted and taken out, the true
        # delay is found.
        rp, body = _behind_delay(3, 3)
        t = np.arange(body.y.size) / body.fs
        hum = sum(1e-2 / k * np.sin(2 * np.pi * 41.7 * k * t + k) for k in (1, 2, 3))
        hummed = Recording(body.u, body.y + hum, body.fs)
        cleaned = without_residual_lines(hummed, BAND, rp.model.A)
        # The core's linear step, fitted with the hum in, bends a little towards a line near a mode.
        assert np.std(cleaned.y - body.y) < 0.2 * np.std(hum)
        assert without_residual_lines(body, BAND, rp.model.A) is body
        extra, _ = refine_delay(rp.model.A, hummed, BAND, 1.0, delay=rp.delay + 3)
        assert extra == -3

    def test_a_cost_that_dips_past_the_answer_is_refitted(self):
        # A core fitted 3 samples short with only two spare poles imitates the missing samples
        # roughly: held fixed, its cost is lowest at the short delay, rises and dips again near
        # the true one; refitted at the answer and the dips, the poles find it.
        rp, short = _behind_delay(0, -3)
        A = _with_spare_poles(rp, [0.3, -0.3])
        n = A.shape[0]
        fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), block_data(short, BAND, 1.0))
        fixed = np.array([linear_cost(fit.A, block_data(compensate_delay(short, j), BAND, 1.0)) for j in range(5)])
        assert np.argmin(fixed) == 0 and fixed[1] > 1.5 * fixed[0] and fixed[3] < fixed[2] < fixed[1]
        extra, costs = refine_delay(fit.A, short, BAND, 1.0, delay=rp.delay - 3)
        assert extra == 3
        assert np.argmin(costs) == 3 and np.isinf(costs).any()

    def test_a_lead_imitated_by_a_pole_at_the_bound_is_read_short_again(self):
        # Random helmet 41 (a 71 Hz high-pass, a 9.6 kHz roll-off) behind a delay read 2 samples long: a core
        # fitted there with a pole started at z = -1 keeps it at the block's radius bound, imitating the lead
        # it cannot have. Refitted from those poles below the onset's delay the core stayed where the long delay
        # put it and the delay read 1 long; with the bound pole replaced first it is read short again, never long.
        rp, body = _behind_delay(41, 2)
        A = lti.real_block_diagonal(np.concatenate([np.linalg.eigvals(rp.model.A), [-0.99999]]))
        n = A.shape[0]
        fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), block_data(body, BAND, 1.0),
                                  max_iterations=20)
        assert np.max(np.abs(np.linalg.eigvals(fit.A))) > 0.9999
        decision = decide_delay(fit.A, body, BAND, 1.0, delay=rp.delay + 2)
        assert -4 <= decision.extra <= -2
        # The refitted cores below the onset's delay come back with the decision (identify starts from them).
        assert decision.extra in decision.fits and set(decision.costs) == set(decision.fits)

    def test_a_delay_already_right_stays(self):
        rp, body = _behind_delay(0, 0)
        extra, costs = refine_delay(rp.model.A, body, BAND, 1.0)
        assert extra == 0 and costs[1] > 2 * costs[0]


class TestWalkDelay:
    def test_a_core_short_of_its_delay_walks_to_it(self):
        # Random helmet 51: a mode of Q 1.1 at 4.8 kHz behind one roll-off, so the response's first samples carry
        # energy; a core fitted 3 samples short with two spare poles imitates them together with the dynamics.
        # Refitted one sample at a time, the cost stays within the noise up to the true delay and rises after it.
        rp, short = _behind_delay(51, -3)
        A = _with_spare_poles(rp, [0.3, -0.3])
        n = A.shape[0]
        fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), block_data(short, BAND, 1.0),
                                  max_iterations=20)
        walk = walk_delay(fit.A, short, BAND, 1.0, start=0)
        assert walk.extra == 3
        assert walk.costs[4] > walk.costs[3] * 1.005 and min(walk.costs) == 0

    def test_the_cores_own_lag_is_not_taken_for_delay(self):
        # The same helmet behind its true delay: its opposite-sign residues put zeros outside the unit circle
        # (an all-pass-like lag of 16 samples of group delay over 20 Hz-4 kHz), but that lag starts at the
        # response's first sample, which a longer delay line cuts: the walk stays.
        rp, body = _behind_delay(51, 0)
        zeros = lti.invariant_zeros(rp.model.A, rp.model.B, rp.model.C, rp.model.D)
        assert np.sum(np.abs(zeros) > 1) >= 4
        walk = walk_delay(rp.model.A, body, BAND, 1.0, start=0)
        assert walk.extra == 0 and walk.costs[1] > walk.costs[0] * 1.01

    def test_a_smoothly_starting_response_is_not_read_long(self):
        # Random helmet 57: two roll-offs at 5.1 and 5.7 kHz (44.1 kHz), so the response starts as t^2 and a
        # longer delay line loses first samples too small to tell; a core with three spare poles behind the true
        # delay. Refitted, the costs rise by less than a sigma^2 a sample for 8 samples, then by 20: the largest
        # delay within 5 sigma^2 of the smallest read 8 samples long. Through costs within the noise of a single
        # parameter the walk errs short.
        rp, body = _behind_delay(57, 0)
        A = _with_spare_poles(rp, [0.3, -0.3, 0.0])
        n = A.shape[0]
        fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), block_data(body, BAND, 1.0),
                                  max_iterations=20)
        walk = walk_delay(fit.A, body, BAND, 1.0, start=0)
        sigma2 = min(walk.costs.values()) / (2 * block_data(body, BAND, 1.0).z.size)
        assert max(walk.costs[j] for j in range(6)) - min(walk.costs.values()) < 5 * sigma2
        assert 0 <= walk.extra <= 2


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
