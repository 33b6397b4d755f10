"""sysid.io.ear_channel: a silent ear channel, or one that does not hear the input, is refused; a healthy one is not."""

import numpy as np
import pytest
import scipy.io.wavfile
from conftest import FAST_OPTIONS

from sysid.core.errors import RecordingError
from sysid.core.thresholds import EAR_COHERENCE_STRETCH, UNCORRELATED_COHERENCE
from sysid.io.ear_channel import check_ear_channel, ear_coherence
from sysid.core.model import Model
from sysid.identify import identify
from sysid.io.recordings import Recording, open_recording, write_wav16
from sysid.random_plant import _continuous_statespace, _zoh_modal
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


# Paths that roll off: below the sensor noise above 1-2 kHz, as a helmet shell makes every feed-forward path.
# A modal sum as sysid.random_plant draws them (its continuous realisation, each mode sampled by ZOH), behind a
# fourth-order roll-off at 1.0-1.3 kHz. Judged by the median coherence over 100 Hz-4 kHz these read 0.06-0.18
# and were refused as disconnected ears, their coherence being 0.94-0.99 from 20 Hz to 1 kHz.
ROLLED_OFF = {
    "fb": [(52.0, 4.7, 1.0)],
    "ff": [(101.0, 26.0, -0.83), (538.0, 3.8, -0.45), (552.0, 6.5, 0.63)],
}
ROLL_OFF_HZ = (1000.0, 1100.0, 1200.0, 1300.0)


def rolled_off_plant(path: str, fs: float = 44100.0):
    A, B, C, D = _zoh_modal(*_continuous_statespace(ROLLED_OFF[path], ROLL_OFF_HZ, None), fs)
    return Model(path=path, fs=fs, A=A, B=B, C=C, D=D)


def rolled_off_session(path: str):
    spec = SessionSpec(path=path, seed=1, output_noise=3e-4, noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)
    return simulate_session(spec, plant=rolled_off_plant(path))


@pytest.mark.parametrize("path", ["fb", "ff"])
def test_a_path_that_rolls_off_is_heard_and_identified_at_the_floor(path, tmp_path):
    files = write_session(rolled_off_session(path), tmp_path / path)
    noise = open_recording(files["noise"])
    sweeps = [open_recording(files[key]).load() for key in ("sweep1", "sweep2")]
    assert ear_coherence(noise) > 5 * UNCORRELATED_COHERENCE
    result = identify(noise, sweeps, path, FAST_OPTIONS)
    assert result.model.identification["rms"] < 1.1 * result.noise_floor


@pytest.mark.parametrize("path", ["fb", "ff"])
def test_an_ear_hearing_noise_shaped_like_the_path_but_unrelated_to_its_input_is_refused(path, tmp_path):
    """The ear's spectrum alone tells nothing: the same path's response to another noise is refused."""
    session = rolled_off_session(path)
    other = simulate_session(SessionSpec(path=path, seed=2, output_noise=3e-4, noise_duration=8.0),
                             plant=rolled_off_plant(path))
    write_wav16(tmp_path / "unrelated.wav", session.noise.u, other.noise.y, 44100)
    with pytest.raises(RecordingError, match=r"unrelated.wav: ear channel 1 does not follow input channel 0 \(\d % of "
                                             r"its power in 20-4000 Hz is coherent with the input\); check the "
                                             "microphone"):
        open_recording(tmp_path / "unrelated.wav")
