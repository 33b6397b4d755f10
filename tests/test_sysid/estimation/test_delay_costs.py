"""The delay from the fixed-pole costs (sysid.estimation.delay.costs): the window around the onset's delay, the
refitted costs where the fixed poles cannot tell, and the detector's scans."""

import numpy as np
import pytest
from delay_sessions import BAND, behind_delay, with_spare_poles

from sysid.core.model import Model
from sysid.estimation.delay import (compensate_delay, fixed_pole_scan, generic_pole_scan, generic_start, refine_delay,
                                    without_residual_lines)
from sysid.estimation.output_error import block_data, linear_cost, refine_output_error
from sysid.io.recordings import Recording


class TestRefineDelay:
    @pytest.mark.parametrize("seed", [0, 3, 7, 12])
    def test_missing_samples_found_from_the_cost_at_the_model_poles(self, seed):
        # A core behind a delay 3 samples short: the true poles plus three spare poles near
        # z = 0 (which imitate z^-3). The fixed-pole cost stays flat up to the true delay and
        # rises after it; plants whose response starts smoothly may be read one sample long.
        rp, body = behind_delay(seed, -3)
        extra, costs = refine_delay(with_spare_poles(rp, [0.0, 0.02, -0.02]), body, BAND, 1.0)
        assert extra in (3, 4)
        assert costs.shape == (5,) and costs[3] <= costs.min() * 1.001

    @pytest.mark.parametrize("seed", [0, 3, 7, 12])
    def test_window_grows_while_the_cost_still_falls(self, seed):
        # 9 samples short with 3 spare poles: the cost falls up to j = 6 (beyond the first
        # window of 4), stays flat to 9 (or one or two more for smooth starts), then rises.
        rp, body = behind_delay(seed, -9)
        extra, costs = refine_delay(with_spare_poles(rp, [0.0, 0.02, -0.02]), body, BAND, 1.0)
        assert 9 <= extra <= 11
        assert costs.size == 13 and costs[0] > 1.5 * costs.min()

    @pytest.mark.parametrize("seed", [0, 3, 12])
    def test_a_delay_read_long_is_shortened(self, seed):
        # The true poles behind a delay 3 samples too long: the core cannot be causal, the
        # fixed-pole cost falls below the onset's delay, and the refitted costs find the true delay.
        rp, body = behind_delay(seed, 3)
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
        rp, body = behind_delay(0, 7)
        extra, costs = refine_delay(rp.model.A, body, BAND, 1.0, delay=rp.delay + 7)
        assert extra == -7
        assert costs.size == 13 and np.argmin(costs) == 1

    def test_hum_is_taken_out_before_the_delay_is_judged(self):
        # An engine order (41.7 Hz and two harmonics) 80 times the sensor noise: no delay fits it, and
        # left in the cost it read this delay 7 samples long (j = +4). Fitted and taken out, the true
        # delay is found.
        rp, body = behind_delay(3, 3)
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
        rp, short = behind_delay(0, -3)
        A = with_spare_poles(rp, [0.3, -0.3])
        n = A.shape[0]
        fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), block_data(short, BAND, 1.0))
        fixed = np.array([linear_cost(fit.A, block_data(compensate_delay(short, j), BAND, 1.0)) for j in range(5)])
        assert np.argmin(fixed) == 0 and fixed[1] > 1.5 * fixed[0] and fixed[3] < fixed[2] < fixed[1]
        extra, costs = refine_delay(fit.A, short, BAND, 1.0, delay=rp.delay - 3)
        assert extra == 3
        assert np.argmin(costs) == 3 and np.isinf(costs).any()

    def test_a_delay_already_right_stays(self):
        rp, body = behind_delay(0, 0)
        extra, costs = refine_delay(rp.model.A, body, BAND, 1.0)
        assert extra == 0 and costs[1] > 2 * costs[0]


class TestFixedPoleScan:
    def test_a_missing_delay_is_the_scans_minimum_coarse_or_full(self):
        # The plant's own poles with 5 samples of its delay left in the data: the cost is least at total delay 5.
        # The coarse scan evaluates every second delay, the model's own and the best one's neighbours, the same
        # costs as the full scan there.
        rp, body = behind_delay(0, -5)
        data = block_data(body, BAND, 1.0)
        best, costs = fixed_pole_scan(rp.model.A, data, 0, max_extra=20)
        assert best == 5 and costs.shape == (21,) and np.all(np.isfinite(costs))
        coarse_best, coarse = fixed_pole_scan(rp.model.A, data, 1, max_extra=19, coarse=True)
        evaluated = np.isfinite(coarse)
        assert coarse_best == 5 and evaluated[::2].all() and evaluated[[1, 4, 5, 6]].all()
        assert np.count_nonzero(evaluated) == 14
        np.testing.assert_array_equal(coarse[evaluated], costs[evaluated])


class TestGenericPoleScan:
    @pytest.mark.parametrize("delay", [30, 80])
    def test_generic_poles_mark_a_delay_short_never_long(self, delay):
        # A pole set that holds no delay, on a one-pole path behind ``delay`` samples: the cost's minimum lies a
        # few samples short of the delay (the generic modes imitate the response's first samples), never past it.
        model = Model(path="fb", fs=44100.0, A=[[0.5]], B=[[1.0]], C=[[1.0]], D=[[0.0]], delay=delay)
        rng = np.random.default_rng(delay)
        u = 0.1 * rng.standard_normal(44100)
        recording = Recording(u, model.simulate(u) + 1e-4 * rng.standard_normal(u.size), model.fs)
        best = generic_pole_scan(block_data(recording, BAND, 1.0), recording.fs, 0, max_extra=100)
        assert delay - 8 <= best <= delay


class TestGenericStart:
    def test_a_start_of_the_given_order_behind_the_delay_refits_to_the_noise(self):
        # Random helmet 3 behind its own delay: the generic poles' fit truncated to the plant's order is a start
        # from which output error reaches the noise, with no fitted model's poles to begin from.
        rp, body = behind_delay(3, 0)
        data = block_data(body, BAND, 1.0)
        start = generic_start(data, body.fs, 0, rp.model.order)
        assert start is not None and start[0].shape == (rp.model.order, rp.model.order)
        assert np.max(np.abs(np.linalg.eigvals(start[0]))) < 1.0
        fit = refine_output_error(*start, data, max_iterations=40)
        truth = linear_cost(rp.model.A, data)
        assert fit.cost_after <= 1.05 * truth
