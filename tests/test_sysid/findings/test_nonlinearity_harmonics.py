"""The input-nonlinearity finding measures the harmonics on the sweeps (Farina) and sets the model's beside them."""

import json

import pytest
from effect_units import true_context

from sysid.findings.nonlinearity import nonlinearity_finding

SATURATION = "input-nonlinearity:h3_db=-22,h2_db=-120,tanh=1"


def test_a_saturation_is_named_with_its_measured_third_harmonic():
    found = nonlinearity_finding(true_context("ff", 5, (SATURATION,)))
    assert found["significant"]
    params = found["params"]
    assert params["measured_h3_db"] == pytest.approx(-22.0, abs=1.0)
    assert params["measured_h2_db"] < -40.0
    assert params["model_h3_db"] < -100.0  # the linear model has none
    assert len(found["evidence"]["measured_h3_curve_db"]) == len(found["evidence"]["harmonic_frequencies_hz"])
    assert "measured" in found["explanation"]
    json.dumps(found.to_dict())  # the diagnosis JSON holds it


def test_a_linear_path_measures_no_harmonics():
    found = nonlinearity_finding(true_context("ff", 5, ()))
    assert not found["significant"]
    assert max(found["params"]["measured_h2_db"], found["params"]["measured_h3_db"]) < -40.0
