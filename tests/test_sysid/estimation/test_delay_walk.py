"""The delay decided (sysid.estimation.delay.walk): the core refitted one sample of delay at a time."""

import numpy as np
from delay_sessions import BAND, behind_delay, with_spare_poles

from sysid.core import lti
from sysid.core.thresholds import WALK_CLEAR, WALK_STEP
from sysid.estimation.delay import decide_delay, walk_delay
from sysid.estimation.output_error import block_data, refine_output_error


class TestDecideDelay:
    def test_a_lead_imitated_by_a_pole_at_the_bound_is_read_short_again(self):
        # Random helmet 41 (a 71 Hz high-pass, a 9.6 kHz roll-off) behind a delay read 2 samples long: a core
        # fitted there with a pole started at z = -1 keeps it at the block's radius bound, imitating the lead
        # it cannot have. Refitted from those poles below the onset's delay the core stayed where the long delay
        # put it and the delay read 1 long; with the bound pole replaced first it is read short again, never long.
        rp, body = behind_delay(41, 2)
        A = lti.real_block_diagonal(np.concatenate([np.linalg.eigvals(rp.model.A), [-0.99999]]))
        n = A.shape[0]
        fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), block_data(body, BAND, 1.0),
                                  max_iterations=20)
        assert np.max(np.abs(np.linalg.eigvals(fit.A))) > 0.9999
        decision = decide_delay(fit.A, body, BAND, 1.0, delay=rp.delay + 2)
        assert -4 <= decision.extra <= -2
        # The refitted cores below the onset's delay come back with the decision (identify starts from them).
        assert decision.extra in decision.fits and set(decision.costs) == set(decision.fits)


class TestWalkDelay:
    def test_a_core_short_of_its_delay_walks_to_it(self):
        # Random helmet 51: a mode of Q 1.1 at 4.8 kHz behind one roll-off, so the response's first samples carry
        # energy; a core fitted 3 samples short with two spare poles imitates them together with the dynamics.
        # Refitted one sample at a time, the cost stays within the noise up to the true delay and rises after it.
        rp, short = behind_delay(51, -3)
        A = with_spare_poles(rp, [0.3, -0.3])
        n = A.shape[0]
        fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), block_data(short, BAND, 1.0),
                                  max_iterations=20)
        walk = walk_delay(fit.A, short, BAND, 1.0, start=0)
        assert walk.extra == 3
        assert walk.costs[4] > walk.costs[3] * 1.005 and min(walk.costs) == 0

    def test_the_cores_own_lag_is_not_taken_for_delay(self):
        # The same helmet behind its true delay: its opposite-sign residues put zeros outside the unit circle
        # (an all-pass-like lag of 16 samples of group delay over 20 Hz-4 kHz), but that lag starts at the
        # response's first sample, which a longer delay line cuts: the walk stays. (Its other zeros sit on the
        # unit circle to round-off, a pair near z = 1 among them, so only those clearly outside are counted.)
        rp, body = behind_delay(51, 0)
        zeros = lti.invariant_zeros(rp.model.A, rp.model.B, rp.model.C, rp.model.D)
        assert np.sum(np.abs(zeros) > 1 + 1e-3) >= 3
        walk = walk_delay(rp.model.A, body, BAND, 1.0, start=0)
        assert walk.extra == 0 and walk.costs[1] > walk.costs[0] * 1.01

    def test_a_smoothly_starting_response_is_not_read_long(self):
        # Random helmet 57: two roll-offs at 5.1 and 5.7 kHz (44.1 kHz), so the response starts as t^2 and a
        # longer delay line loses first samples too small to tell; a core with three spare poles behind the true
        # delay. Refitted, the costs creep up by a fraction of a sigma^2 a sample for several samples, then rise by
        # tens: where in that creep the walk stops depends on how far each refit converged (differences of a
        # sigma^2, round-off from one machine to the next), so what is asserted is the rule, not a sample: the
        # walk never passes the clear rise, it errs short of the largest delay within 5 sigma^2 of the smallest
        # (which read this helmet 8 samples long), and every delay it passes costs within WALK_STEP sigma^2.
        rp, body = behind_delay(57, 0)
        A = with_spare_poles(rp, [0.3, -0.3, 0.0])
        n = A.shape[0]
        fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), block_data(body, BAND, 1.0),
                                  max_iterations=20)
        walk = walk_delay(fit.A, body, BAND, 1.0, start=0)
        sigma2 = min(walk.costs.values()) / (2 * block_data(body, BAND, 1.0).z.size)
        rise = {j: (cost - min(walk.costs.values())) / sigma2 for j, cost in walk.costs.items()}
        assert max(rise[j] for j in range(6)) < 5
        clear_rise = min(j for j in rise if j > 0 and rise[j] > WALK_CLEAR)
        within_five = max(j for j in rise if j < clear_rise and rise[j] < 5)
        assert 0 <= walk.extra < clear_rise and walk.extra <= within_five
        smallest = min(rise, key=rise.get)
        assert all(rise[j] <= WALK_STEP * (1 + 1e-9) for j in range(smallest, walk.extra + 1))
