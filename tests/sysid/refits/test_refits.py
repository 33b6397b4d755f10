"""refits: the delay a data correction's refit is identified behind (``refits._shorter_delays``), and a
structure step that unmasks a delay read long (``refits.add_periodic_disturbance``)."""

import numpy as np
import pytest
from effect_sessions import TEST_REFIT

from sysid import refits
from sysid.core import lti
from sysid.core.errors import IdentificationError
from sysid.core.model import Model
from sysid.estimation.delay import compensate_delay
from sysid.estimation.output_error import block_data, refine_output_error
from sysid.random_plant import random_plant, random_session
from sysid.refits import _corrected_refit, _shorter_delays, add_periodic_disturbance
from sysid.validation.compare import compare

TRANSIENT_S = 0.5


def _core_read_long(rp, session, by: int) -> Model:
    """Random helmet ``rp``'s poles and a spare one at z = -1 fitted behind a delay ``by`` samples long."""
    long = rp.delay + by
    body = compensate_delay(session.noise.trimmed(TRANSIENT_S), long)
    A = lti.real_block_diagonal(np.concatenate([np.linalg.eigvals(rp.model.A), [-0.99999]]))
    n = A.shape[0]
    fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)),
                              block_data(body, max_seconds=1.0), max_iterations=20)
    return Model(path="fb", fs=rp.fs, A=fit.A, B=fit.B, C=fit.C, D=fit.D, delay=long)


@pytest.mark.slow
def test_a_core_behind_a_delay_read_long_is_identified_behind_a_shorter_one():
    # Random helmet 3 (one mode at 101 Hz of Q 21, a 33 Hz high-pass, pure delay 17) behind a delay 3 samples
    # long, its core fitted there with a spare pole started at z = -1 (what a core does with a lead it cannot
    # have): 4.7x the floor. Identified anew behind shorter delays (up to refits.SHORTER_BY), 18 reaches the
    # floor (1.0x; 10-15 s of CPU, four identifications at most).
    seed = 3
    rp = random_plant(seed)
    session = random_session(seed, noise_duration=4.0, sweep_duration=1.0, sweep_silence=0.2)
    model = _core_read_long(rp, session, 3)
    long = model.delay
    after = compare(model, session.sweeps)
    best, best_after = _shorter_delays(model, after, session.noise, session.sweeps, TEST_REFIT, TRANSIENT_S)
    assert best.delay < long and abs(best.delay - rp.delay) <= 2
    assert after.ratio > 2.0 and best_after.ratio < 1.2


@pytest.mark.slow
def test_modelling_a_hum_unmasks_a_delay_read_long():
    # The same core read 3 samples long on a session with a 60 Hz hum (three harmonics): before the hum is
    # modelled it dominates the validation error, so no delay shorter than the model's validates visibly
    # better; once its lines are modelled the delay's own error shows (above the floor) and the step
    # identifies the core behind shorter delays too (refits._unmasked_delay).
    seed = 3
    rp = random_plant(seed)
    session = random_session(seed, noise_duration=4.0, sweep_duration=1.0, sweep_silence=0.2,
                             effects=["periodic-disturbance:60.0,3,1e-3"])
    model = _core_read_long(rp, session, 3)
    refined, params = add_periodic_disturbance(model, session.noise, session.sweeps, {"frequencies_hz": [60.0, 120.0, 180.0]},
                                               TEST_REFIT, TRANSIENT_S)
    assert params["frequencies_hz"] == [60.0, 120.0, 180.0]
    assert refined.delay < model.delay and abs(refined.delay - rp.delay) <= 2
    assert compare(refined, session.sweeps).ratio < 1.2


def test_a_correction_whose_starts_are_all_unstable_returns_the_trial_for_the_caller_to_refuse(monkeypatch):
    # The trial (corrections applied, core kept) and its warm start both unstable, and no stable model in the
    # fresh fit's grid: the unstable trial comes back (refine's _refinement refuses it in one line), not a
    # ValueError from choosing among no candidates.
    session = random_session(3, noise_duration=4.0, sweep_duration=1.0, sweep_silence=0.2)
    trial = Model(path="fb", fs=session.noise.fs, A=np.array([[1.01]]), B=np.array([[1.0]]), C=np.array([[0.1]]),
                  D=np.zeros((1, 1)), delay=3)
    fresh_calls = []

    def no_stable_model(*args):
        fresh_calls.append(args)
        raise IdentificationError("no stable model in the grid")

    monkeypatch.setattr(refits, "_warm", lambda t, *args: t)
    monkeypatch.setattr(refits, "_fresh", no_stable_model)
    result = _corrected_refit(trial, session.noise, session.sweeps, TEST_REFIT, TRANSIENT_S)
    assert result is trial and not result.stable
    assert len(fresh_calls) == 1
