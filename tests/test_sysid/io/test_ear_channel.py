"""sysid.io.ear_channel: a silent ear channel, or one that does not hear the input, is refused; a healthy one is not."""

import numpy as np
import pytest
import scipy.io.wavfile

from sysid.core.errors import RecordingError
from sysid.core.thresholds import EAR_COHERENCE_STRETCH, UNCORRELATED_COHERENCE
from sysid.io.ear_channel import check_ear_channel, ear_coherence
from sysid.io.recordings import Recording, open_recording, write_wav16
from sysid.simulate import SessionSpec, simulate_session, write_session


def test_an_ear_following_the_input_has_coherence_one(rng):
    u = 0.1 * rng.standard_normal(3 * EAR_COHERENCE_STRETCH)
    assert ear_coherence(Recording(u, 0.5 * u, 44100.0, "gain")) == pytest.approx(1.0, abs=1e-9)


def test_a_recording_shorter_than_one_stretch_is_not_judged(rng):
    u = 0.1 * rng.standard_normal(EAR_COHERENCE_STRETCH - 1)
    assert ear_coherence(Recording(u, u, 44100.0, "short")) is None


def test_an_ear_channel_below_the_silence_level_is_refused_with_the_fix(tmp_path, rng):
    u = 0.1 * rng.standard_normal(4410)
    write_wav16(tmp_path / "a.wav", u, 0.5 * u, 44100)
    recording = open_recording(tmp_path / "a.wav")
    with pytest.raises(RecordingError, match=r"a.wav: ear channel 1 is silent \(disconnected microphone\?\); check the "
                                             "microphone, or choose the channels with --input-channel/--output-channel"):
        check_ear_channel(recording, 0.0, recording.length)


@pytest.mark.parametrize("ppm", [-150.0, 60.0])
def test_a_drifting_ear_clock_is_not_a_disconnected_ear(ppm, tmp_path):
    """An ear clock off by tens to hundreds of ppm turns the cross-spectrum's phase over a whole
    noise recording (median coherence 0.01 at 60 ppm over 20 s); judged per stretch it is heard."""
    spec = SessionSpec(path="ff", seed=3, noise_duration=20.0, sweep_duration=2.0)
    files = write_session(simulate_session(spec, effects=(f"clock-drift:{ppm}",)), tmp_path / "rig")
    for key in ("noise", "sweep1"):
        recording = open_recording(files[key])
        assert ear_coherence(recording) > 5 * UNCORRELATED_COHERENCE


def test_an_ear_hearing_only_noise_is_refused_whatever_the_stretch(tmp_path):
    rng = np.random.default_rng(7)
    # Two independent noises, shaped as the loader tests' stereo signals (tanh keeps them off the rails).
    x = np.tanh(np.stack([0.3 * rng.standard_normal(20 * 44100), 0.2 * rng.standard_normal(20 * 44100)], axis=1))
    x = x - x.mean(axis=0)
    path = tmp_path / "unrelated.wav"
    scipy.io.wavfile.write(path, 44100, x)
    with pytest.raises(RecordingError, match="does not follow input channel"):
        open_recording(path)
