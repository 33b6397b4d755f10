"""Wiener-Hammerstein drivers in the self-identified workflow (issue 28): a coupling high-pass in front of the driver.

A random helmet (``sysid.random_plant``) whose drive passes a first-order high-pass at 2 or 20 Hz, then the
asymmetric driver u + a2 u^2 (second harmonic -15 to -30 dB at the sweeps' amplitude), then the path: the
model identified on that session names input-nonlinearity among its top two findings, and ``refine --auto``
brings it within 1.5x of the noise floor with the core within two states of the true plant's order (the
pre-filter fitted with the map and the core, ``sysid.estimation.wiener_hammerstein``, where the static map
does not reach the floor).
"""

import numpy as np
import pytest
from nonlinear_cases import polynomial_session, refined_to_the_floor

from sysid.core.model import Model
from sysid.estimation.input_nonlinearity import harmonic_levels


def coupled_session(seed: int, path: str, corner_hz: float, level_db: float):
    """The session of u + a2 u^2 (second harmonic ``level_db`` at the sweeps' amplitude) behind a first-order
    high-pass at ``corner_hz``."""
    return polynomial_session(seed, path, level_db, extra=f",prefilter_hz={corner_hz}")


def check_refined_to_the_floor(seed, path, corner_hz, level_db):
    session = coupled_session(seed, path, corner_hz, level_db)
    true = Model.from_dict(session.truth["plant"])
    assert true.input_nonlinearity_form["prefilter"]["corner_hz"] == corner_hz
    sweep_amplitude = float(np.max(np.abs(session.sweeps[0].u)))
    assert harmonic_levels(true.static_input_nonlinearity, sweep_amplitude)[2] == pytest.approx(level_db, abs=0.2)
    auto, text, _ = refined_to_the_floor(session, path)
    # The map the data ask for, polynomial or saturation: at -30 dB behind 2 Hz a tanh with an offset holds
    # u + a2 u^2 as well (random helmet 8 FB: 1.05x the floor).
    refined = auto.model.input_nonlinearity is not None or auto.model.input_nonlinearity_form is not None
    assert refined and harmonic_levels(auto.model.static_input_nonlinearity, sweep_amplitude)[2] == \
        pytest.approx(level_db, abs=1.0), text
    return auto


# The default run: the FB path of a small helmet behind a 20 Hz coupling high-pass, where the static map alone
# ends at 36x the floor; the pre-filter must be found near its corner.
def test_a_coupling_highpass_before_the_driver_is_refined_to_the_floor():
    auto = check_refined_to_the_floor(3, "fb", 20.0, -20.0)
    prefilter = auto.model.input_nonlinearity_form["prefilter"]
    assert prefilter["order"] == 1 and prefilter["corner_hz"] == pytest.approx(20.0, rel=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("seed, path, corner_hz, level_db", [
    (3, "fb", 2.0, -15.0), (3, "ff", 20.0, -30.0), (3, "ff", 2.0, -22.0), (3, "fb", 20.0, -30.0),
    (8, "fb", 20.0, -15.0), (8, "fb", 2.0, -30.0), (8, "ff", 20.0, -22.0), (8, "ff", 2.0, -15.0)])
def test_coupled_drivers_on_random_helmets(seed, path, corner_hz, level_db):
    check_refined_to_the_floor(seed, path, corner_hz, level_db)
