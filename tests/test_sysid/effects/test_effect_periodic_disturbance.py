"""periodic-disturbance: lines the input lacks are found at their frequency and level."""

import numpy as np
import pytest
from effect_units import true_context

from sysid.findings.disturbance import disturbance_finding
from sysid.io.lines import find_lines


def test_a_tone_in_noise_is_a_line_and_a_driven_tone_is_not():
    rng = np.random.default_rng(0)
    fs, n = 44100.0, 88200
    t = np.arange(n) / fs
    u = rng.standard_normal(n)
    tone = np.sqrt(2) * 0.01 * np.sin(2 * np.pi * 60.0 * t)
    lines = find_lines(1e-3 * rng.standard_normal(n) + tone, u, fs)
    assert len(lines) == 1 and lines[0][0] == pytest.approx(60.0, abs=0.2) and lines[0][2] == pytest.approx(0.01, rel=0.05)
    assert find_lines(1e-3 * rng.standard_normal(n) + tone, u + 10 * tone, fs) == []


def test_hum_and_its_harmonics_are_found():
    found = disturbance_finding(true_context("ff", 5, ("periodic-disturbance:50,3,1e-3",)))
    assert found["significant"]
    assert found["params"]["frequencies_hz"] == pytest.approx([50.0, 100.0, 150.0], abs=0.2)


def test_no_line_on_a_clean_session():
    assert not disturbance_finding(true_context("ff", 5, ()))["significant"]


@pytest.mark.parametrize("q", [30.0, 100.0])
def test_a_mode_the_model_lacks_is_no_line(q):
    # A lightly damped mode missing from the model peaks in its residual like a line where the input is
    # flat, but the input explains it (sysid.io.lines.driven): the resonance finding's, not this one's.
    found = disturbance_finding(true_context("ff", 5, (f"resonance:130,{q:g},12",)))
    assert not found["significant"], found
