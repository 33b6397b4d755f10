"""Tests of the noise to cancel from a recording with ANC off and the FF model (anc.disturbance.from_recording)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.signal

from anc.disturbance import from_recording

from control_cases import INCOHERENT_DB, recording_with_anc_off, seed_pair

# Third-octave-wide checks inside the chin's band, away from its edges (Welch bins of 10 Hz).
CHECKED_HZ = np.geomspace(100.0, 1000.0, 11)


def _band_db(values: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
    """10 log10 of the mean of values over a third octave around each checked frequency."""
    out = []
    for centre in CHECKED_HZ:
        m = (frequencies >= centre / 2 ** (1 / 6)) & (frequencies < centre * 2 ** (1 / 6))
        out.append(10.0 * np.log10(np.mean(values[m]) + 1e-300))
    return np.array(out)


@pytest.fixture(scope="module")
def seed_ff():
    pair = seed_pair()
    return pair.p, recording_with_anc_off(pair.p, seconds=3.0)


def test_with_the_true_model_the_residual_is_the_incoherent_noise(seed_ff):
    p_true, recording = seed_ff
    disturbance = from_recording(recording, ff_model=p_true)
    f = disturbance.frequencies_hz
    coherent = np.abs(p_true.frequency_response(f)) ** 2 * disturbance.reference_psd
    # The recording's ear noise not coherent with the chin is INCOHERENT_DB below the coherent part in every band.
    level = _band_db(disturbance.incoherent_psd(), f) - _band_db(coherent, f)
    np.testing.assert_allclose(level, INCOHERENT_DB, atol=1.5)
    # Nothing of the chin is left in the residual: the missed path is far below the incoherent noise.
    missed = _band_db(np.abs(disturbance.model_error) ** 2 * disturbance.reference_psd, f)
    assert np.all(missed < _band_db(disturbance.incoherent_psd(), f) - 10.0)


def test_the_path_a_model_misses_is_measured_with_its_phase(seed_ff):
    p_true, recording = seed_ff
    # A model 10 % low misses P_true - P_model = 0.1 P_true, 20 dB below the chin-coherent ear noise.
    wrong = dataclasses.replace(p_true, C=0.9 * p_true.C)
    disturbance = from_recording(recording, ff_model=wrong)
    f = CHECKED_HZ
    spectra = disturbance.at(f)
    np.testing.assert_allclose(spectra.coherent_response(), p_true.frequency_response(f),
                               rtol=0.02, atol=0.0)
    np.testing.assert_allclose(spectra.model_error, p_true.frequency_response(f) - wrong.frequency_response(f),
                               rtol=0.2, atol=0.0)
    # The incoherent part stays the recording's own, not the missed path's.
    level = _band_db(disturbance.incoherent_psd(), disturbance.frequencies_hz) - _band_db(
        np.abs(p_true.frequency_response(disturbance.frequencies_hz)) ** 2 * disturbance.reference_psd,
        disturbance.frequencies_hz)
    np.testing.assert_allclose(level, INCOHERENT_DB, atol=1.5)


def test_the_ear_power_is_the_recordings_and_nothing_is_made_of_silence(seed_ff):
    p_true, recording = seed_ff
    disturbance = from_recording(recording, ff_model=dataclasses.replace(p_true, C=0.9 * p_true.C))
    f = disturbance.frequencies_hz
    # Above the chin's band the chin microphone has (next to) no power: E stays finite and the rest non-negative.
    assert np.all(np.isfinite(disturbance.model_error)) and np.all(disturbance.incoherent_psd() >= 0.0)
    # The coherent part (model and missed path) plus the rest is the recording's own ear PSD.
    _, recorded = scipy.signal.welch(recording.y, recording.fs, nperseg=f.size * 2 - 2)
    np.testing.assert_allclose(_band_db(disturbance.ear_psd, f), _band_db(recorded, f), atol=0.3)


def test_as_the_models_see_it_the_missed_path_is_noise(seed_ff):
    p_true, recording = seed_ff
    wrong = dataclasses.replace(p_true, C=0.9 * p_true.C)
    recorded = from_recording(recording, ff_model=wrong)
    modelled = recorded.modelled()
    f = recorded.frequencies_hz
    assert modelled.model_error is None and modelled.modelled() is modelled
    np.testing.assert_array_equal(modelled.coherent_response(), recorded.at(f).modelled().coherent_response())
    np.testing.assert_allclose(modelled.at(CHECKED_HZ).coherent_response(), wrong.frequency_response(CHECKED_HZ),
                               rtol=1e-9)
    # The whole residual is noise to the models: 20 dB of missed path over the 40 dB incoherent floor.
    np.testing.assert_array_equal(modelled.incoherent_psd(), recorded.residual_psd)
    level = _band_db(modelled.incoherent_psd(), f) - _band_db(recorded.incoherent_psd(), f)
    assert np.all(level > 15.0)
    # Only the recorded path holds the recording's ear power: |P_model|^2 + |E|^2 leaves out 2 Re(P_model E*), 0.9 dB
    # for a model 10 % low (0.81 + 0.01 of |P|^2 against 1).
    _, ear = scipy.signal.welch(recording.y, recording.fs, nperseg=f.size * 2 - 2)
    np.testing.assert_allclose(_band_db(modelled.ear_psd, f) - _band_db(ear, f), 10 * np.log10(0.82), atol=0.2)
