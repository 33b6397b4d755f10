"""The input-nonlinearity finding measures the harmonics on the sweeps (Farina) and sets the model's beside them."""

import json

import numpy as np
import pytest
from effect_units import true_context

from sysid.estimation.input_nonlinearity import SweepHarmonics
from sysid.findings.nonlinearity import MISSED_DB, nonlinearity_finding, refuted_by_sweeps

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


def _measured(h2_db: float, h3_db: float, snr2: float, snr3: float, amplitude: float = 0.5) -> SweepHarmonics:
    return SweepHarmonics({2: h2_db, 3: h3_db}, np.array([100.0]), {2: np.array([h2_db]), 3: np.array([h3_db])},
                          amplitude, 1.0, {2: snr2, 3: snr3})


def test_a_claimed_harmonic_the_sweeps_do_not_show_is_refuted():
    """The regression claims H3 -29.7 dB at 0.5 FS (a3 = -0.52, random helmet 535 FB read 2 samples late); the
    separated third harmonic is at the noise, -64.9 dB: refuted. Measured within MISSED_DB of the claim: kept."""
    a3 = -0.5238
    assert refuted_by_sweeps(-0.016, a3, _measured(-63.9, -64.9, 0.98, 1.06))
    assert not refuted_by_sweeps(-0.016, a3, _measured(-63.9, -29.7 - MISSED_DB + 1.0, 0.98, 3000.0))


def test_a_claim_below_the_sweeps_noise_is_not_refuted():
    """A harmonic the sweeps could not see (claimed below FARINA_SNR times the noise in its window) is no
    evidence against the regression, which reads the noise recording's larger amplitudes too."""
    # H3 claimed -70 dB at 0.5 FS; the window's noise at -65 dB: unseen, so not refuted.
    a3 = 4 * 10 ** (-70 / 20) / 0.25
    assert not refuted_by_sweeps(0.0, a3, _measured(-64.0, -65.0, 1.0, 1.0))
    assert not refuted_by_sweeps(0.0, a3, SweepHarmonics({2: -64.0, 3: -65.0}, np.array([100.0]), {}, 0.5, 1.0, None))
