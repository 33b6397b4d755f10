"""refits.structures: a structure step that unmasks a delay read long (``add_periodic_disturbance``)."""

import pytest
from delay_sessions import core_read_long
from effect_sessions import TEST_REFIT

from sysid.random_plant import random_plant, random_session
from sysid.refits.structures import add_periodic_disturbance
from sysid.validation.compare import compare

TRANSIENT_S = 0.5


@pytest.mark.slow
def test_modelling_a_hum_unmasks_a_delay_read_long():
    # A core read 3 samples long on a session with a 60 Hz hum (three harmonics): before the hum is
    # modelled it dominates the validation error, so no delay shorter than the model's validates visibly
    # better; once its lines are modelled the delay's own error shows (above the floor) and the step
    # identifies the core behind shorter delays too (refits.machinery._unmasked_delay).
    seed = 3
    rp = random_plant(seed)
    session = random_session(seed, noise_duration=4.0, sweep_duration=1.0, sweep_silence=0.2,
                             effects=["periodic-disturbance:60.0,3,1e-3"])
    model = core_read_long(rp, session, 3, TRANSIENT_S)
    refined, params = add_periodic_disturbance(model, session.noise, session.sweeps, {"frequencies_hz": [60.0, 120.0, 180.0]},
                                               TEST_REFIT, TRANSIENT_S)
    assert params["frequencies_hz"] == [60.0, 120.0, 180.0]
    assert refined.delay < model.delay and abs(refined.delay - rp.delay) <= 2
    assert compare(refined, session.sweeps).ratio < 1.2
