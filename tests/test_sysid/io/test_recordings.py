"""Loading recordings: scaling of every PCM format and every bad input of the contract."""

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.io.wavfile

from sysid.core.errors import RecordingError
from sysid.io.recordings import (RecordingWarning, check_same_rate, load_recording, open_recording,
                                 recording_from_arrays, write_wav16)


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


def _heard(rng, n):
    """Stereo test signals whose ear channel follows the input (longer files are checked for that)."""
    x = _stereo(rng, n)
    return np.stack([x[:, 0], 0.6 * x[:, 0] + 0.2 * x[:, 1]], axis=1)


def _write_pcm(path, frames: np.ndarray, bits: int, tag: int = 1, extensible: bool = False) -> None:
    """A stereo PCM/float WAV written by hand (24-bit and WAVE_FORMAT_EXTENSIBLE, which scipy does not write)."""
    import struct

    width = bits // 8
    if bits == 24:
        codes = frames.astype("<i4").view(np.uint8).reshape(frames.shape + (4,))[..., :3]
        data = codes.tobytes()
    else:
        data = frames.astype({(1, 16): "<i2", (1, 32): "<i4", (3, 32): "<f4", (1, 64): "<i8"}[(tag, bits)]).tobytes()
    channels = frames.shape[1]
    head = struct.pack("<HHIIHH", 0xFFFE if extensible else tag, channels, 44100, 44100 * width * channels,
                       width * channels, bits)
    if extensible:
        head += struct.pack("<HHI", 22, bits, 3) + struct.pack("<H", tag) + b"\x00\x00\x00\x00\x10\x00\x80\x00\x00\xaa\x00\x38\x9b\x71"
    body = b"WAVE" + b"fmt " + struct.pack("<I", len(head)) + head + b"data" + struct.pack("<I", len(data)) + data
    Path(path).write_bytes(b"RIFF" + struct.pack("<I", len(body)) + body)


class TestRecordingFile:
    """open_recording reads blocks from the file; every view equals the same slice of the loaded recording."""

    @pytest.mark.parametrize("bits, extensible", [(16, False), (24, False), (24, True), (32, False)])
    def test_pcm_formats_scale_like_the_contract(self, tmp_path, rng, bits, extensible):
        codes = np.round(_stereo(rng) * 2 ** (bits - 1)).astype(np.int64)
        _write_pcm(tmp_path / "a.wav", codes, bits, extensible=extensible)
        rec = load_recording(tmp_path / "a.wav")
        np.testing.assert_array_equal(rec.u, codes[:, 0] / 2.0 ** (bits - 1))
        np.testing.assert_array_equal(rec.y, codes[:, 1] / 2.0 ** (bits - 1))

    @pytest.mark.parametrize("kind", ["int16", "int24", "float32"])
    def test_windows_equal_slices_in_memory(self, tmp_path, rng, kind):
        x = _heard(rng, 20000)
        if kind == "int16":
            write_wav16(tmp_path / "a.wav", x[:, 0], x[:, 1], 44100)
        elif kind == "int24":
            _write_pcm(tmp_path / "a.wav", np.round(x * 2**23).astype(np.int64), 24)
        else:
            scipy.io.wavfile.write(tmp_path / "a.wav", 44100, x.astype(np.float32))
        whole = load_recording(tmp_path / "a.wav")
        lazy = open_recording(tmp_path / "a.wav")
        assert (lazy.length, lazy.fs, lazy.path) == (whole.u.size, whole.fs, whole.path)
        view = lazy.trimmed(0.1).advanced(7)
        first = 4410
        u, y = view.read(100, 5100)
        np.testing.assert_array_equal(u, whole.u[first + 100:first + 5100])
        np.testing.assert_array_equal(y, whole.y[first + 107:first + 5107])
        head = view.head(0.2)
        np.testing.assert_array_equal(head.u, whole.u[first:first + 8820])
        np.testing.assert_array_equal(head.y, whole.y[first + 7:first + 8827])
        assert view.length == whole.u.size - first - 7
        np.testing.assert_array_equal(lazy.load().y, whole.y)
        blocks = list(view.blocks(4000))
        assert [b[0].size for b in blocks] == [4000] * 3 + [view.length - 12000]
        np.testing.assert_array_equal(np.concatenate([b[1] for b in blocks]), whole.y[first + 7:])

    def test_spectra_of_the_file_equal_those_in_memory_and_are_read_in_blocks(self, tmp_path, rng, monkeypatch):
        from sysid.estimation.spectra import estimate_spectra
        from sysid.io import wav

        x = _stereo(rng, 60000)
        write_wav16(tmp_path / "a.wav", x[:, 0], 0.5 * x[:, 0] + 0.1 * x[:, 1], 44100)
        lazy = open_recording(tmp_path / "a.wav").trimmed(0.1)
        reads = []
        real = wav.read_frames
        monkeypatch.setattr(wav, "read_frames", lambda *a: reads.append(a[3] - a[2]) or real(*a))
        for estimator in ("h1", "seed-average"):
            streamed = estimate_spectra(lazy, estimator, nperseg=500)
            reference = estimate_spectra(load_recording(tmp_path / "a.wav").trimmed(0.1), estimator, nperseg=500)
            np.testing.assert_allclose(streamed.s_yu, reference.s_yu, rtol=1e-9, atol=1e-12 * np.max(np.abs(reference.s_yu)))
            assert streamed.segments == reference.segments
        # 256 segments of 500 samples at 50 % overlap per read, never the whole file.
        assert 0 < max(reads) <= 255 * 250 + 500

    def test_quality_of_a_long_file_is_judged_block_by_block(self, tmp_path, rng, monkeypatch):
        from sysid.io import recordings

        x = _heard(rng, 40000)
        y = x[:, 1].copy()
        y[1000:1090:2] = 1.5  # 90 samples at both rails inside the first block only
        y[1001:1090:2] = -1.5
        write_wav16(tmp_path / "clip.wav", x[:, 0] + 0.05, y, 44100)
        monkeypatch.setattr(recordings, "QUALITY_BLOCK", 10000)
        with pytest.warns(RecordingWarning) as record:
            lazy = open_recording(tmp_path / "clip.wav")
        messages = sorted(str(w.message).split("clip.wav: ")[1] for w in record)
        assert re.fullmatch(r"input channel has a DC offset of 0\.0(49|50)\d* FS", messages[0])
        assert messages[1] == "output channel clipped on 0.225 % of samples"
        assert lazy.clipped_fraction[1] == pytest.approx(90 / 40000)
        assert lazy.dc_offset[0] == pytest.approx(0.05, abs=2e-3)

    @pytest.mark.parametrize("bits, tag, message", [
        (64, 1, r"unsupported sample format \(64-bit integer in 8-byte samples\)"),
        (16, 2, r"not a readable WAV file \(format code 0x0002 is neither PCM nor IEEE float\)"),
    ])
    def test_unsupported_formats_are_one_line_errors(self, tmp_path, bits, tag, message):
        _write_pcm(tmp_path / "odd.wav", np.ones((100, 2), np.int64), bits if tag == 1 else 16, tag=1)
        if tag != 1:
            blob = bytearray((tmp_path / "odd.wav").read_bytes())
            blob[20:22] = tag.to_bytes(2, "little")
            (tmp_path / "odd.wav").write_bytes(bytes(blob))
        with pytest.raises(RecordingError, match="odd.wav: " + message):
            open_recording(tmp_path / "odd.wav")

    def test_a_file_cut_short_after_opening_is_a_one_line_error(self, tmp_path, rng):
        x = _stereo(rng)
        write_wav16(tmp_path / "a.wav", x[:, 0], x[:, 1], 44100)
        lazy = open_recording(tmp_path / "a.wav")
        with open(tmp_path / "a.wav", "r+b") as handle:
            handle.truncate(1000)
        with pytest.raises(RecordingError, match="a.wav: the file is shorter than when it was opened"):
            lazy.read(0, lazy.length)
