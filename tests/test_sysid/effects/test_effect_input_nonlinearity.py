"""input-nonlinearity: the harmonics of a known polynomial are estimated from the sweep residual."""

import numpy as np
import pytest
from conftest import SHORT
from effect_units import true_context

from sysid.core.model import Model
from sysid.findings import DiagnosisContext
from sysid.estimation.input_polynomial import polynomial_columns
from sysid.findings.nonlinearity import nonlinearity_finding
from sysid.random_plant import random_session
from sysid.validation.compare import compare


def test_the_columns_are_the_linear_part_of_the_powers():
    ctx = true_context("ff", 5, ())
    u = ctx.sweeps[0].u
    columns = polynomial_columns(ctx.model, u)
    assert np.allclose(columns[:, 0], ctx.model.simulate(u))
    assert np.allclose(columns[:, 2], ctx.model.simulate(u**3))
    assert abs(np.mean(columns[:, 1])) < 1e-3  # the even power is centred


@pytest.mark.parametrize("h2, h3", [(-35.0, -35.0), (-30.0, -60.0)])
def test_harmonic_levels_are_estimated(h2, h3):
    found = nonlinearity_finding(true_context("ff", 5, (f"input-nonlinearity:{h2},{h3}",)))
    assert found["significant"]
    assert found["params"]["h2_db"] == pytest.approx(h2, abs=1.0)
    if h3 > -50:
        assert found["params"]["h3_db"] == pytest.approx(h3, abs=1.0)


def test_nothing_on_a_linear_path():
    assert not nonlinearity_finding(true_context("ff", 5, ()))["significant"]


def test_levels_are_stated_at_the_sessions_largest_input():
    # simulate states the levels at the session's largest input; on random helmet 100 the noise
    # recording's peaks lie 2.6 dB above the sweeps' amplitude (read at the sweeps': H2 2.6 dB low).
    session = random_session(100, "fb", effects=["input-nonlinearity:-33.4,-35.7"], **SHORT)
    assert np.max(np.abs(session.noise.u)) > 1.2 * max(np.max(np.abs(s.u)) for s in session.sweeps)
    model = Model.from_dict(session.truth["base_plant"])
    found = nonlinearity_finding(DiagnosisContext(model, session.noise, session.sweeps, compare(model, session.sweeps)))
    assert found["params"]["h2_db"] == pytest.approx(-33.4, abs=1.0)
    assert found["params"]["h3_db"] == pytest.approx(-35.7, abs=1.0)


@pytest.mark.parametrize("compressive, sign", [(0, 1.0), (1, -1.0)])
def test_the_cubic_term_takes_either_sign(compressive, sign):
    # compressive=1 simulates u - |a3| u^3 (a hardening suspension): H3 at the stated level all the same,
    # its third harmonic in antiphase with the fundamental (a sine's peaks flattened, not sharpened).
    session = random_session(3, "fb", effects=[f"input-nonlinearity:h2_db=-120,h3_db=-25,compressive={compressive}"],
                             **SHORT)
    record = session.truth["effects"][0]
    a3 = record["coefficients"][2]
    assert np.sign(a3) == sign
    amplitude = record["reference_amplitude"]
    assert 20 * np.log10(abs(a3) * amplitude**2 / 4) == pytest.approx(-25.0, abs=1e-9)
    peak = Model.from_dict(session.truth["plant"]).apply_input_nonlinearity(np.array([amplitude]))[0]
    assert (peak - amplitude) * sign > 0


def test_an_existing_polynomial_stays_expanding():
    # Sessions simulated before the sign existed keep their coefficients: the default is u + a3 u^3.
    spec = "input-nonlinearity:-33.4,-35.7"
    session = random_session(100, "fb", effects=[spec], **SHORT)
    assert session.truth["effects"][0]["coefficients"][2] > 0
