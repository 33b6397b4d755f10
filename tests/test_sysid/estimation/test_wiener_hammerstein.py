"""The Wiener-Hammerstein fit: the pre-filter's corner and order found with the map and the core by output error."""

from dataclasses import replace

import numpy as np
import pytest
from conftest import SHORT

from sysid.core.model import Model
from sysid.estimation.wiener_hammerstein import fit_wiener_hammerstein
from sysid.random_plant import random_session
from sysid.validation.compare import compare


def test_the_corner_of_a_coupling_highpass_is_found_from_the_bare_core():
    session = random_session(3, "fb", effects=["input-nonlinearity:h2_db=-15,h3_db=-120,prefilter_hz=20"], **SHORT)
    true = Model.from_dict(session.truth["plant"])
    # The true core without its input block: the pre-filter's linear part is missing from it, as from a core
    # identified on the session before the map.
    start = replace(true, input_nonlinearity=None, input_nonlinearity_form=None)
    fit = fit_wiener_hammerstein(start, session.noise, "polynomial", 2.0, 5.0, session.spec.transient_s)
    model = fit.model(start)
    assert fit.form["kind"] == "identity"
    assert fit.form["prefilter"]["order"] == 1
    assert fit.form["prefilter"]["corner_hz"] == pytest.approx(20.0, rel=0.05)
    assert fit.coefficients[1] == pytest.approx(true.input_nonlinearity[1], rel=0.1)
    assert compare(model, session.sweeps).ratio <= 1.2
    assert fit.cost_after < fit.cost_before
    assert np.array_equal(model.A.shape, true.A.shape)
