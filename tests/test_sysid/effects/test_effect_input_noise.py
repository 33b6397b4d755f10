"""input-noise: the input noise density read from the repeated sweeps, the bound it sets on the validation error."""

import pytest
from effect_units import true_context, true_session

from sysid.core.model import Model
from sysid.findings.input_noise import bound_ratio, bound_share, input_noise_density, input_noise_finding
from sysid.validation.compare import compare


def test_the_density_of_white_input_noise_is_read_from_the_sweeps():
    # White noise of standard deviation s has one-sided density 2 s^2 / fs (FS^2/Hz).
    session = true_session("ff", 5, ("input-noise:5",))
    sigma = next(e for e in session.truth["effects"] if e["effect"] == "input-noise")["input_noise_rms"]
    density = input_noise_density(session.sweeps)
    assert density == pytest.approx(2 * sigma**2 / session.noise.fs, rel=0.15)


def test_input_noise_is_significant_only_when_present():
    assert input_noise_finding(true_context("ff", 5, ("input-noise:5",)))["significant"]
    assert not input_noise_finding(true_context("ff", 5, ()))["significant"]


def test_the_bound_is_what_the_true_path_validates_at():
    # The input's own noise through the path is in every prediction: the true path itself validates
    # at the bound, far above the floor, and the finding names it with the input SNR read two ways.
    session = true_session("ff", 5, ("input-noise:5",))
    model = Model.from_dict(session.truth["base_plant"])
    comparison = compare(model, session.sweeps)
    assert comparison.ratio > 3.0
    assert bound_ratio(model, session.sweeps, comparison.noise_floor) == pytest.approx(comparison.ratio, rel=0.1)
    found = input_noise_finding(true_context("ff", 5, ("input-noise:5",)))
    assert found["significant"] and found["evidence"]["bounds_the_error"]
    assert found["params"]["bound_ratio"] == pytest.approx(comparison.ratio, rel=0.1)
    assert found["params"]["input_snr_db"] == pytest.approx(5.0, abs=1.0)
    assert found["evidence"]["input_snr_coherence_db"] == pytest.approx(5.0, abs=1.5)


def test_no_bound_without_input_noise():
    found = input_noise_finding(true_context("ff", 5, ()))
    assert found["params"]["bound_ratio"] < 1.1 and not found["evidence"]["bounds_the_error"]


def test_a_model_far_above_the_floor_for_another_effect_is_not_bounded_by_the_input_noise():
    # Every input channel has some noise (the sessions' converter noise leaves the true path near
    # 1.1x): with a resonance missing the error is far above that, and input noise is not what bounds it.
    context = true_context("fb", 5, ("resonance:f0_hz=1400,q=8,gain_db=12",))
    found = input_noise_finding(context)
    assert context.excess > 5.0
    assert not found["significant"] and not found["evidence"]["bounds_the_error"], found["explanation"]


def test_the_bound_share_is_the_error_power_above_the_floor_it_accounts_for():
    assert bound_share(1.5, 1.2) == 1.0
    assert bound_share(2.0, 4.0) == pytest.approx(3.0 / 15.0)
    assert bound_share(1.1, 73.0) < 1e-3
