"""The delay tried on the sweeps (sysid.estimation.delay.trials): a decided delay is kept when a core behind it
validates."""

import numpy as np
from delay_sessions import BAND, with_spare_poles

from sysid.core.model import Model
from sysid.estimation.delay import TrialOptions, compensate_delay, moved_delay
from sysid.estimation.order_search import OrderCandidate, sweep_rms
from sysid.estimation.output_error import block_data, refine_output_error
from sysid.random_plant import random_plant, random_session
from sysid.validation.sweeps import VALIDATION_BAND, simulated_rms, sweep_spectrum

OPTIONS = TrialOptions(BAND, VALIDATION_BAND, 1.0, 2.0, False, 0.03)


def _pick_behind(seed: int, off_by: int):
    """(random plant, session, noise body behind its delay + ``off_by``, a pick fitted there with two spare poles
    from a ``grid gamma=100`` start, its validation rms, and the validation by simulation)."""
    rp = random_plant(seed)
    session = random_session(seed, noise_duration=5.0, sweep_duration=0.5)
    delay = rp.delay + off_by
    body = compensate_delay(session.noise.trimmed(3.0), delay)
    A = with_spare_poles(rp, [0.3, -0.3])
    n = A.shape[0]
    fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), block_data(body, BAND, 1.0),
                              max_iterations=20)
    spectra = [sweep_spectrum(compensate_delay(s, delay), VALIDATION_BAND) for s in session.sweeps]
    pick = OrderCandidate(n, "grid gamma=100", sweep_rms(fit.A, fit.B, fit.C, fit.D, spectra), fit.A, fit.B, fit.C,
                          fit.D, gamma=100)

    def validate(c, d):
        return simulated_rms(Model(path="fb", fs=rp.fs, A=c.A, B=c.B, C=c.C, D=c.D, delay=d), session.sweeps,
                             VALIDATION_BAND)

    return rp, session, body, delay, pick, validate


class TestMovedDelay:
    def test_a_pick_short_of_its_delay_moves_behind_it(self):
        # Random helmet 51 (a mode of Q 1.1 at 4.8 kHz behind a roll-off) fitted 3 samples short: its core
        # decides the 3 samples, and a core refitted behind them validates as well: the pick moves there,
        # with the noise block and the sweeps' spectra behind the new delay, and keeps its start's gamma.
        rp, session, body, delay, pick, validate = _pick_behind(51, -3)
        moved = moved_delay(pick, validate(pick, delay), [pick], body, session.sweeps, delay, validate, OPTIONS)
        assert moved is not None and moved.extra == 3
        assert moved.rms <= validate(pick, delay) * 1.03 and moved.pick.gamma == 100
        assert moved.body.u.size == body.u.size - 3
        assert moved.sweep_spectra[0].frequencies.size == sweep_spectrum(
            compensate_delay(session.sweeps[0], delay + 3), VALIDATION_BAND).frequencies.size

    def test_a_pick_behind_its_true_delay_stays(self):
        rp, session, body, delay, pick, validate = _pick_behind(0, 0)
        assert moved_delay(pick, validate(pick, delay), [pick], body, session.sweeps, delay, validate, OPTIONS) is None
