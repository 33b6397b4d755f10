"""input-noise: the input noise density read from the repeated sweeps."""

import pytest

from sysid.findings.input_noise import input_noise_density, input_noise_finding

from effect_units import true_context, true_session


def test_the_density_of_white_input_noise_is_read_from_the_sweeps():
    # White noise of standard deviation s has one-sided density 2 s^2 / fs (FS^2/Hz).
    session = true_session("ff", 5, ("input-noise:5",))
    sigma = next(e for e in session.truth["effects"] if e["effect"] == "input-noise")["input_noise_rms"]
    density = input_noise_density(session.sweeps)
    assert density == pytest.approx(2 * sigma**2 / session.noise.fs, rel=0.15)


def test_input_noise_is_significant_only_when_present():
    assert input_noise_finding(true_context("ff", 5, ("input-noise:5",)))["significant"]
    assert not input_noise_finding(true_context("ff", 5, ()))["significant"]
