"""Harmonic levels of a static map, the saturation of given levels, the drive limit, Farina's sweep harmonics."""

import math
from dataclasses import replace

import numpy as np
import pytest

from sysid.core.plants import appendix_a_model
from sysid.estimation.input_nonlinearity import (drive_limit, harmonic_levels, saturation_form, sweep_harmonics,
                                                 tanh_map)
from sysid.io.recordings import Recording
from sysid.simulate import SessionSpec, sweep_signal


def test_harmonic_levels_of_a_polynomial_are_the_textbook_ones():
    # u = A sin: a2 u^2 gives a2 A / 2 at 2f, a3 u^3 gives a3 A^2 / 4 at 3f (to first order in a3).
    a2, a3, amplitude = 0.1, 0.01, 0.5
    levels = harmonic_levels(lambda u: u + a2 * u**2 + a3 * u**3, amplitude)
    assert levels[2] == pytest.approx(20 * math.log10(a2 * amplitude / 2 / (1 + 3 * a3 * amplitude**2 / 4)), abs=1e-6)
    assert levels[3] == pytest.approx(20 * math.log10(a3 * amplitude**2 / 4 / (1 + 3 * a3 * amplitude**2 / 4)),
                                      abs=1e-6)


@pytest.mark.parametrize("h3, h2", [(-15.0, -120.0), (-22.0, -25.0), (-30.0, -120.0)])
def test_the_saturation_has_the_levels_asked_for(h3, h2):
    form = saturation_form(h3, h2, 0.4)
    levels = harmonic_levels(lambda u: tanh_map(u, form["scale"], form["offset"]), 0.4)
    # The offset lowers the third harmonic a little; the scale is solved on the symmetric form.
    assert levels[3] == pytest.approx(h3, abs=0.5 if h2 > -120 else 1e-6)
    if h2 > -120:
        assert levels[2] == pytest.approx(h2, abs=1e-6)
    else:
        assert form["offset"] == 0.0


def test_a_tanh_cannot_give_a_square_wave():
    with pytest.raises(ValueError, match="below -10 dB"):
        saturation_form(-8.0, -120.0, 0.4)


def test_drive_limit_is_where_the_distortion_reaches_the_level():
    model = replace(appendix_a_model("fb"), input_nonlinearity_form=saturation_form(-20.0, -120.0, 0.3))
    limit = drive_limit(model)
    # The symmetric tanh's distortion is nearly all third harmonic: -20 dB at 0.3 FS, by construction.
    assert limit == pytest.approx(0.3, rel=0.02)
    assert drive_limit(model, -40.0) < limit
    assert drive_limit(appendix_a_model("fb")) is None
    assert drive_limit(replace(appendix_a_model("fb"), input_nonlinearity=[1.0, 0.0, -1e-6])) is None  # beyond 16 FS


def _hammerstein_sweeps(static_map, method="logarithmic", repeats=1):
    spec = SessionSpec(fs=44100.0, sweep_duration=2.0, sweep_silence=0.2, sweep_method=method)
    u = 0.5 * sweep_signal(spec)
    y = appendix_a_model("ff").simulate(static_map(u))
    rng = np.random.default_rng(0)
    return [Recording(u, y + 1e-4 * rng.standard_normal(u.size), spec.fs, f"sweep{k}.wav") for k in range(repeats)]


def test_sweep_harmonics_read_the_maps_levels_on_an_exponential_sweep():
    form = saturation_form(-24.0, -30.0, 0.5)
    measured = sweep_harmonics(_hammerstein_sweeps(lambda u: tanh_map(u, form["scale"], form["offset"])))
    truth = harmonic_levels(lambda u: tanh_map(u, form["scale"], form["offset"]), 0.5)
    assert measured.amplitude == pytest.approx(0.5, rel=1e-3)
    assert measured.levels_db[2] == pytest.approx(truth[2], abs=0.5)
    assert measured.levels_db[3] == pytest.approx(truth[3], abs=0.5)
    assert measured.rate_s == pytest.approx(2.0 / math.log(200.0), rel=0.02)


def test_a_linear_path_shows_no_harmonics_and_a_linear_sweep_none():
    measured = sweep_harmonics(_hammerstein_sweeps(lambda u: u))
    assert max(measured.levels_db.values()) < -50
    assert sweep_harmonics(_hammerstein_sweeps(lambda u: u, method="linear")) is None


def test_the_harmonics_are_judged_against_the_output_noise_of_the_repeated_sweeps():
    # Two sweeps of one excitation: their difference is noise alone, read in each harmonic's window.
    clean = sweep_harmonics(_hammerstein_sweeps(lambda u: u, repeats=2))
    assert all(0.5 < v < 2.0 for v in clean.snr.values())  # noise reads as noise: a ratio near 1
    form = saturation_form(-30.0, -120.0, 0.5)
    saturated = sweep_harmonics(_hammerstein_sweeps(lambda u: tanh_map(u, form["scale"]), repeats=2))
    assert saturated.snr[3] > 100.0
    assert sweep_harmonics(_hammerstein_sweeps(lambda u: u)).snr is None  # one sweep: no noise reference
