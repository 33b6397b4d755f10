"""Bounded memory: identify reads a noise recording of any length from its file in blocks.

The default run checks that the streamed path (``open_recording``) gives the in-memory
model to rounding; the slow run identifies a 10-minute recording in a child process and
bounds its peak resident memory (``ru_maxrss``), which the in-memory path exceeds.
"""

import numpy as np
import pytest
from conftest import FAST_OPTIONS
from long_sessions import measure_identify, noise_blocks, write_long_noise

from sysid.identify import identify
from sysid.io.recordings import load_recording, open_recording

PEAK_LIMIT_MB = 500.0
BAND = np.linspace(20.0, 5000.0, 400)


def test_streamed_identification_equals_in_memory(identifications, session_files):
    """The FF session's noise read from its file in blocks gives the in-memory identification to rounding."""
    reference = identifications["ff"]
    sweeps = [load_recording(session_files[key]) for key in ("sweep1", "sweep2")]
    result = identify(open_recording(session_files["noise"]), sweeps, "ff", FAST_OPTIONS)
    for name in ("s_uu", "s_yu", "s_yy"):
        expected = getattr(reference.spectra, name)
        np.testing.assert_allclose(getattr(result.spectra, name), expected, rtol=1e-9, atol=1e-12 * np.max(np.abs(expected)))
    model, expected = result.model, reference.model
    assert (model.order, model.delay) == (expected.order, expected.delay)
    assert model.identification["seed_choice"]["gamma"] == expected.identification["seed_choice"]["gamma"]
    assert model.identification["rms"] == pytest.approx(expected.identification["rms"], rel=1e-6)
    H, H_expected = model.frequency_response(BAND), expected.frequency_response(BAND)
    assert np.max(np.abs(H - H_expected) / np.abs(H_expected)) < 1e-6
    np.testing.assert_allclose(model.uncertainty["relative_95"], expected.uncertainty["relative_95"], rtol=1e-6, atol=1e-9)


def test_long_noise_is_the_plant_driven_by_the_session_noise(sessions):
    """The block-wise generator: state carried across blocks, the session's input level."""
    session = sessions["ff"]
    quiet = type(session)(session.spec.__class__(**{**session.spec.__dict__, "input_noise": 0.0, "output_noise": 0.0}),
                          session.plant, session.noise, session.sweeps, session.truth)
    blocks = list(noise_blocks(quiet, 1.0, block_seconds=0.3))
    u = np.concatenate([b[0] for b in blocks])
    y = np.concatenate([b[1] for b in blocks])
    assert len(blocks) == 4 and u.size == 44100
    np.testing.assert_allclose(y, session.plant.simulate(u), atol=1e-12 * np.max(np.abs(y)))
    assert np.std(u) == pytest.approx(np.std(session.noise.u[3 * 44100:]), rel=0.05)


@pytest.mark.slow
def test_ten_minute_recording_is_identified_in_bounded_memory(sessions, session_files, tmp_path):
    """10 minutes of noise (106 MB of WAV, 2.2 GB when identified in memory) under 500 MB peak, at the floor."""
    noise = write_long_noise(tmp_path / "noise_10min.wav", sessions["ff"], 600.0)
    sweeps = [session_files["sweep1"], session_files["sweep2"]]
    measured = measure_identify(noise, sweeps, "ff", streamed=True, options={"gammas": FAST_OPTIONS.gammas})
    assert measured["peak_mb"] < PEAK_LIMIT_MB, measured["peak_mb"]
    assert measured["rms"] < 1.2 * measured["noise_floor"]
