"""Loading recordings: scaling of every PCM format and every bad input of the contract."""

import warnings

import numpy as np
import pytest
import scipy.io.wavfile

from sysid.errors import RecordingError
from sysid.recordings import RecordingWarning, check_same_rate, load_recording, recording_from_arrays, write_wav16


def _stereo(rng, n=4410):
    # tanh keeps the peaks below the rails without the flat tops of a hard clip (which is clipping).
    x = np.tanh(np.stack([0.3 * rng.standard_normal(n), 0.2 * rng.standard_normal(n)], axis=1))
    return x - x.mean(axis=0)


class TestScaling:
    def test_int16_round_trip_within_half_lsb(self, tmp_path, rng):
        x = _stereo(rng)
        write_wav16(tmp_path / "a.wav", x[:, 0], x[:, 1], 44100)
        rec = load_recording(tmp_path / "a.wav")
        assert rec.fs == 44100.0
        assert np.max(np.abs(rec.u - x[:, 0])) <= 0.5 / 32768 + 1e-12
        assert np.max(np.abs(rec.y - x[:, 1])) <= 0.5 / 32768 + 1e-12

    def test_int32_and_float_formats_are_full_scale(self, tmp_path, rng):
        x = _stereo(rng)
        scipy.io.wavfile.write(tmp_path / "i32.wav", 44100, np.round(x * 2**31).astype(np.int32))
        scipy.io.wavfile.write(tmp_path / "f32.wav", 44100, x.astype(np.float32))
        for name in ("i32.wav", "f32.wav"):
            rec = load_recording(tmp_path / name)
            np.testing.assert_allclose(rec.u, x[:, 0], atol=1e-7)

    def test_channels_can_be_swapped(self, tmp_path, rng):
        x = _stereo(rng)
        write_wav16(tmp_path / "a.wav", x[:, 0], x[:, 1], 44100)
        rec = load_recording(tmp_path / "a.wav", input_channel=1, output_channel=0)
        np.testing.assert_allclose(rec.u, x[:, 1], atol=1 / 32768)


class TestBadInput:
    def test_mono_file(self, tmp_path):
        scipy.io.wavfile.write(tmp_path / "mono.wav", 44100, np.ones(100, np.int16))
        with pytest.raises(RecordingError, match=r"mono.wav: mono file"):
            load_recording(tmp_path / "mono.wav")

    def test_wrong_channel_index(self, tmp_path, rng):
        x = _stereo(rng)
        write_wav16(tmp_path / "a.wav", x[:, 0], x[:, 1], 44100)
        with pytest.raises(RecordingError, match=r"a.wav: output channel 2 does not exist \(file has 2 channels\)"):
            load_recording(tmp_path / "a.wav", output_channel=2)

    def test_corrupt_header(self, tmp_path):
        (tmp_path / "bad.wav").write_bytes(b"RIFF\x10\x00\x00\x00WAVEjunkjunk")
        with pytest.raises(RecordingError, match=r"bad.wav: not a readable WAV file"):
            load_recording(tmp_path / "bad.wav")

    def test_missing_file(self, tmp_path):
        with pytest.raises(RecordingError, match=r"nothere.wav: no such file"):
            load_recording(tmp_path / "nothere.wav")

    def test_nan_samples(self, tmp_path, rng):
        x = _stereo(rng).astype(np.float32)
        x[10, 1] = np.nan
        scipy.io.wavfile.write(tmp_path / "nan.wav", 44100, x)
        with pytest.raises(RecordingError, match=r"nan.wav: output channel has NaN or infinite samples"):
            load_recording(tmp_path / "nan.wav")

    def test_silent_input(self, tmp_path, rng):
        x = _stereo(rng)
        write_wav16(tmp_path / "silent.wav", np.zeros(len(x)), x[:, 1], 44100)
        with pytest.raises(RecordingError, match=r"silent.wav: input channel is silent"):
            load_recording(tmp_path / "silent.wav")

    def test_sample_rate_mismatch(self, rng):
        a = recording_from_arrays(rng.standard_normal(10) * 0.1, rng.standard_normal(10) * 0.1, 44100, "a.wav")
        b = recording_from_arrays(rng.standard_normal(10) * 0.1, rng.standard_normal(10) * 0.1, 48000, "b.wav")
        with pytest.raises(RecordingError, match=r"b.wav: sample rate 48000 Hz differs from 44100 Hz of a.wav"):
            check_same_rate([a, b])

    def test_arrays_of_different_length(self):
        with pytest.raises(RecordingError, match="input has 3 samples but output has 2"):
            recording_from_arrays([0.1, 0.2, 0.3], [0.1, 0.2], 44100)


class TestQualityFindings:
    def test_clipping_is_a_warning_with_its_fraction(self, tmp_path, rng):
        x = _stereo(rng)
        y = x[:, 1].copy()
        y[:45:2] = 1.5  # 45 of 4410 samples driven past both rails
        y[1:45:2] = -1.5
        write_wav16(tmp_path / "clip.wav", x[:, 0], y, 44100)
        with pytest.warns(RecordingWarning, match=r"clip.wav: output channel clipped on 1.02 % of samples"):
            rec = load_recording(tmp_path / "clip.wav")
        assert rec.clipped_fraction[1] == pytest.approx(45 / 4410)
        assert rec.clipped_fraction[0] == 0.0

    def test_dc_offset_is_a_warning_with_its_value(self, tmp_path, rng):
        x = _stereo(rng)
        write_wav16(tmp_path / "dc.wav", x[:, 0] + 0.05, x[:, 1], 44100)
        with pytest.warns(RecordingWarning, match=r"dc.wav: input channel has a DC offset of 0\.05\d* FS"):
            rec = load_recording(tmp_path / "dc.wav")
        assert rec.dc_offset[0] == pytest.approx(0.05, abs=2e-3)

    def test_clean_recording_has_no_warning(self, tmp_path, rng):
        x = _stereo(rng)
        write_wav16(tmp_path / "ok.wav", x[:, 0], x[:, 1], 44100)
        with warnings.catch_warnings():
            warnings.simplefilter("error", RecordingWarning)
            rec = load_recording(tmp_path / "ok.wav")
        assert rec.clipped_fraction == (0.0, 0.0) and rec.dc_offset == (0.0, 0.0)


def test_slow_plant_response_is_not_a_dc_offset(sessions):
    """The FB plant's pole at z = 0.99991 leaves a slow tail after a sweep's start; not an offset."""
    sweep = sessions["fb"].sweeps[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordingWarning)
        rec = recording_from_arrays(sweep.u, sweep.y, sweep.fs, "fb_sweep")
    assert rec.dc_offset == (0.0, 0.0)
    with pytest.warns(RecordingWarning, match="fb_sweep: output channel has a DC offset of 0.01"):
        shifted = recording_from_arrays(sweep.u, sweep.y + 0.01, sweep.fs, "fb_sweep")
    # The 2 s sweep is mostly the plant's slow tail, which biases the part means: detection, rough value.
    assert shifted.dc_offset[1] == pytest.approx(0.01, abs=4e-3)
