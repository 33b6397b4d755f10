"""The bound a design respects (anc.uncertainty): the stated band where it holds, else the vouched gain."""

from __future__ import annotations

import numpy as np

from anc.uncertainty import LINEARISATION_LIMIT, model_uncertainty
from sysid.core.model import Model
from sysid.core.plants import appendix_a_model


def _with_band(frequencies, relative):
    s = appendix_a_model("fb")
    return Model.from_dict({**s.to_dict(), "uncertainty": {"frequencies_hz": frequencies, "relative_95": relative}})


def test_stated_band_is_used_where_it_holds():
    model = _with_band([20.0, 100.0, 1000.0], [0.1, 0.3, 0.05])
    u = model_uncertainty(model)
    np.testing.assert_allclose(u.at([20.0, 100.0, 1000.0]), [0.1, 0.3, 0.05])
    assert u.source == "the model's uncertainty field"


def test_outside_and_unreliable_bound_covers_any_phase_within_the_vouched_gain():
    """Outside 20 Hz-1 kHz and where the stated error is >= 100 % (200-300 Hz), the bound is
    1 + B / |S_model|: a truth of gain B and any phase lies inside it; below the band B grows as 1/f."""
    f_stated = [20.0, 199.0, 200.0, 300.0, 301.0, 1000.0]
    model = _with_band(f_stated, [0.1, 0.1, 1.5, 1.5, 0.1, 0.1])
    u = model_uncertainty(model)
    f = np.array([5.0, 10.0, 250.0, 4000.0])
    magnitude = np.abs(model.frequency_response(f))
    bound = (u.at(f) - 1.0) * magnitude                 # B(f)
    grid = np.geomspace(20.0, 1000.0, 2000)
    vouched = 1.1 * np.abs(model.frequency_response(grid[(grid < 199.0) | (grid > 301.0)]))
    assert np.all(bound[2:] >= 0.99 * vouched.max())
    # Below the band: at least the 20 Hz vouched gain times 20 / f.
    np.testing.assert_array_less(1.1 * np.abs(model.frequency_response([20.0]))[0] * 20.0 / f[:2], 1.01 * bound[:2])
    assert np.all(u.unknown(f)) and not np.any(u.unknown([50.0, 500.0]))
    assert np.all(u.at([250.0]) >= 1.5) and LINEARISATION_LIMIT == 1.0


def test_seed_fb_path_below_the_band_lies_inside_the_bound():
    """The seed FB path rises as 1/f below 20 Hz to 30x its 20 Hz gain at DC (a pole at 0.9999); the bound
    its own default band (20 Hz-5 kHz) implies there, B(f) = (r - 1) |S(f)|, is at least that gain."""
    s = appendix_a_model("fb")
    u = model_uncertainty(s)
    f = np.geomspace(0.2, 19.0, 200)
    magnitude = np.abs(s.frequency_response(f))
    assert np.all(magnitude <= (u.at(f) - 1.0) * magnitude + 1e-12)


def test_non_finite_band_entries_state_nothing():
    """A NaN in the band (a failed covariance) is treated as 'nothing known' there, never as 0 %."""
    s = appendix_a_model("fb")
    model = Model.from_dict({**s.to_dict(), "uncertainty": {"frequencies_hz": [20.0, 100.0, 1000.0],
                                                             "relative_95": [0.1, 0.1, 0.1]}})
    model.uncertainty["relative_95"] = [0.1, float("nan"), 0.1]
    u = model_uncertainty(model)
    assert u.unknown([100.0])[0] and u.at([100.0])[0] >= 1.0 and np.isfinite(u.at([100.0])[0])
