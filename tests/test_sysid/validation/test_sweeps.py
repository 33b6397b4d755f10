"""Validation rms, its compressed evaluation for the grid, and the sweeps' noise floor."""

import numpy as np
import pytest

from sysid.core import lti
from sysid.io.recordings import Recording
from sysid.validation.sweeps import (CompressedValidation, band_rms, noise_floor, repeat_lines, rms_from_responses,
                                     simulated_rms, sweep_spectrum, without_repeat_lines)


def test_band_rms_of_a_sine_inside_and_outside_the_band():
    fs = 44100.0
    t = np.arange(44100) / fs
    x = 0.3 * np.sin(2 * np.pi * 1000 * t) + 0.2 * np.sin(2 * np.pi * 10000 * t)
    assert band_rms(x, fs, (20, 4000)) == pytest.approx(0.3 / np.sqrt(2), rel=1e-6)
    assert band_rms(x, fs, (5000, 15000)) == pytest.approx(0.2 / np.sqrt(2), rel=1e-6)


def test_true_plant_rms_is_the_output_noise_and_matches_the_noise_floor(sessions):
    session = sessions["ff"]
    floor = noise_floor(*session.sweeps)
    true_rms = simulated_rms(session.plant, session.sweeps)
    # White output noise of 2e-4 FS (plus quantisation) has this share in 20 Hz - 4 kHz:
    expected = np.sqrt(2e-4**2 + (2**-15) ** 2 / 12) * np.sqrt((4000 - 20) / 22050)
    assert floor == pytest.approx(expected, rel=0.05)
    assert true_rms == pytest.approx(floor, rel=0.05)


def test_noise_floor_aligns_repeats_recorded_with_an_offset(sessions):
    a, b = sessions["ff"].sweeps
    shifted = Recording(np.concatenate([np.zeros(300), b.u]), np.concatenate([np.zeros(300), b.y]), b.fs, "late.wav")
    assert noise_floor(a, shifted) == pytest.approx(noise_floor(a, b), rel=0.02)


def test_frequency_domain_rms_equals_time_domain_simulation(sessions):
    session = sessions["fb"]
    spectra = [sweep_spectrum(s) for s in session.sweeps]
    responses = [session.plant.frequency_response(s.frequencies) for s in spectra]
    assert rms_from_responses(spectra, responses) == pytest.approx(simulated_rms(session.plant, session.sweeps), rel=0.02)


@pytest.mark.parametrize("cell_hz,tolerance", [(2.0, 2e-3), (1.0, 5e-4)])
def test_compressed_validation_matches_exact_rms(sessions, cell_hz, tolerance):
    """Error of order (cell / mode bandwidth)^2: halving the cell quarters it."""
    session = sessions["ff"]
    spectra = [sweep_spectrum(s) for s in session.sweeps]
    compressed = CompressedValidation(spectra, cell_hz)
    plant = session.plant
    z = np.exp(2j * np.pi * compressed.frequencies / plant.fs)
    for gain in (1.0, 1.01, 0.9):
        coarse = gain * lti.frequency_response(plant.A, plant.B, plant.C, plant.D, z)
        exact = rms_from_responses(spectra, [gain * plant.frequency_response(s.frequencies) for s in spectra])
        assert compressed.rms(coarse[None, :])[0] == pytest.approx(exact, rel=tolerance)


@pytest.mark.parametrize("length", [1000, 4001, 2 * 3 * 5 * 7 * 11, 3 * 7 * 2741, 2 * 1009, 1103, 2 * 3 * 881])
def test_sweep_spectrum_equals_the_real_dfts_at_any_length(length):
    # Lengths with a large prime factor take one complex DFT of u + j y; the bins must be the real DFTs'.
    rng = np.random.default_rng(length)
    u, y = rng.standard_normal(length), rng.standard_normal(length)
    spectrum = sweep_spectrum(Recording(u, y, 8000.0), band=(0.0, 4000.0), skip_s=0.0)
    np.testing.assert_allclose(spectrum.U, np.fft.rfft(u), rtol=0, atol=1e-12 * np.sqrt(length))
    np.testing.assert_allclose(spectrum.Y, np.fft.rfft(y), rtol=0, atol=1e-12 * np.sqrt(length))


def _hummed(recording: Recording, phase: float) -> Recording:
    """The recording with a 50 Hz hum and two harmonics (1e-3 / k FS rms) at its own phase."""
    t = np.arange(recording.y.size) / recording.fs
    hum = sum(np.sqrt(2) * 1e-3 / k * np.sin(2 * np.pi * 50.0 * k * t + k * phase) for k in (1, 2, 3))
    return Recording(recording.u, recording.y + hum, recording.fs, recording.path)


def test_a_hum_not_locked_to_the_sweeps_is_no_output_noise(sessions):
    # The repeats' difference keeps a hum of random phase (1.2e-3 FS, five times the floor): fitted out
    # of the difference, the floor is the one without it, and the true plant validates at it on the
    # sweeps with the lines taken out beside the sweep's response.
    session = sessions["fb"]
    clean = noise_floor(*session.sweeps)
    hummed = [_hummed(s, phase) for s, phase in zip(session.sweeps, (0.3, 2.1))]
    assert repeat_lines(*session.sweeps) == []
    assert repeat_lines(*hummed) == pytest.approx([50.0, 100.0, 150.0], abs=0.05)
    assert noise_floor(*hummed) == pytest.approx(clean, rel=0.02)
    cleaned, lines = without_repeat_lines(*hummed)
    assert len(lines) == 3
    assert simulated_rms(session.plant, hummed) > 5 * clean
    assert simulated_rms(session.plant, cleaned) == pytest.approx(simulated_rms(session.plant, session.sweeps), rel=0.05)
    # A clean session is left as it is.
    same, none = without_repeat_lines(*session.sweeps)
    assert none == [] and all(a is b for a, b in zip(same, session.sweeps))
