"""refits.machinery: the delay a data correction's refit is identified behind (``_shorter_delays``)."""

import pytest
from delay_sessions import core_read_long
from effect_sessions import TEST_REFIT

from sysid.random_plant import random_plant, random_session
from sysid.refits.machinery import _shorter_delays
from sysid.validation.compare import compare

TRANSIENT_S = 0.5


@pytest.mark.slow
def test_a_core_behind_a_delay_read_long_is_identified_behind_a_shorter_one():
    # Random helmet 3 (one mode at 101 Hz of Q 21, a 33 Hz high-pass, pure delay 17) behind a delay 3 samples
    # long, its core fitted there with a spare pole started at z = -1 (what a core does with a lead it cannot
    # have): 4.7x the floor. Identified anew behind shorter delays (up to thresholds.SHORTER_BY), 18 reaches the
    # floor (1.0x; 10-15 s of CPU, four identifications at most).
    seed = 3
    rp = random_plant(seed)
    session = random_session(seed, noise_duration=4.0, sweep_duration=1.0, sweep_silence=0.2)
    model = core_read_long(rp, session, 3, TRANSIENT_S)
    long = model.delay
    after = compare(model, session.sweeps)
    best, best_after = _shorter_delays(model, after, session.noise, session.sweeps, TEST_REFIT, TRANSIENT_S)
    assert best.delay < long and abs(best.delay - rp.delay) <= 2
    assert after.ratio > 2.0 and best_after.ratio < 1.2
