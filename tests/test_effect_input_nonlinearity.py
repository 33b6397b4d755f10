"""input-nonlinearity: the harmonics of a known polynomial are estimated from the sweep residual."""

import numpy as np
import pytest

from sysid.findings.nonlinearity import nonlinearity_finding, polynomial_columns

from effect_units import true_context


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
