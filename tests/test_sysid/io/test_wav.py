"""sysid.io.wav: the header's layout, every sample format's decoding and full-scale scaling, 16-bit writing."""

import struct

import numpy as np
import pytest
import scipy.io.wavfile

from sysid.core.errors import RecordingError
from sysid.io import wav


def _frames(path):
    layout = wav.read_layout(path)
    return layout, wav.read_frames(str(path), layout, 0, layout.frames)


class TestReadLayout:
    def test_a_16_bit_stereo_file(self, tmp_path):
        scipy.io.wavfile.write(tmp_path / "a.wav", 48000, np.zeros((10, 2), np.int16))
        layout = wav.read_layout(tmp_path / "a.wav")
        assert (layout.fs, layout.channels, layout.block_align, layout.sample_bytes) == (48000.0, 2, 4, 2)
        assert (layout.data_offset, layout.frames, layout.dtype) == (44, 10, np.dtype("<i2"))

    def test_chunks_before_the_data_are_skipped_with_their_pad_byte(self, tmp_path):
        fmt = struct.pack("<HHIIHH", 1, 2, 44100, 44100 * 4, 4, 16)
        data = np.arange(6, dtype="<i2").tobytes()
        body = (b"WAVE" + b"fmt " + struct.pack("<I", 16) + fmt + b"LIST" + struct.pack("<I", 3) + b"abc\x00"
                + b"data" + struct.pack("<I", len(data)) + data)
        (tmp_path / "a.wav").write_bytes(b"RIFF" + struct.pack("<I", len(body)) + body)
        layout, frames = _frames(tmp_path / "a.wav")
        assert layout.frames == 3
        np.testing.assert_array_equal(wav.decode(frames, layout, 1), [1, 3, 5])

    def test_a_data_chunk_longer_than_the_file_is_cut_to_whole_frames(self, tmp_path):
        wav.write_wav16(tmp_path / "a.wav", np.zeros(10), np.zeros(10), 44100)
        blob = (tmp_path / "a.wav").read_bytes()
        (tmp_path / "a.wav").write_bytes(blob[:-6])  # 10 frames of 4 bytes, the last one and a half cut
        assert wav.read_layout(tmp_path / "a.wav").frames == 8

    @pytest.mark.parametrize("blob, reason", [
        (b"RIFX\x00\x00\x00\x04WAVE", "no fmt chunk"),
        (b"RIFF\x04\x00\x00\x00WAVE", "no fmt chunk"),
        (b"RIFF\x0c\x00\x00\x00WAVEdata\x00\x00\x00\x00", "data chunk before the fmt chunk"),
        (b"OggS\x00\x00\x00\x00WAVE", "no RIFF/WAVE header"),
    ])
    def test_what_is_no_wav_file_is_named_in_one_line(self, tmp_path, blob, reason):
        (tmp_path / "x.wav").write_bytes(blob)
        with pytest.raises(RecordingError, match=f"x.wav: not a readable WAV file \\({reason}\\)$"):
            wav.read_layout(tmp_path / "x.wav")


class TestFullScale:
    @pytest.mark.parametrize("dtype, codes, expected", [
        (np.uint8, [0, 128, 255], [-1.0, 0.0, 127 / 128]),
        (np.int16, [-32768, 0, 32767], [-1.0, 0.0, 32767 / 32768]),
        (np.int32, [-2**31, 0, 2**31 - 256], [-1.0, 0.0, (2**31 - 256) / 2**31]),
        (np.float32, [-1.0, 0.25, 1.0], [-1.0, 0.25, 1.0]),
    ])
    def test_the_rails_and_zero_of_every_format(self, dtype, codes, expected):
        samples = wav.full_scale(np.array(codes, dtype=dtype))
        assert samples.dtype == np.float64
        np.testing.assert_array_equal(samples, expected)

    @pytest.mark.parametrize("dtype, rails", [
        ("u1", (-1.0, 127 / 128)), ("<i2", (-1.0, 32767 / 32768)), ("<i4", (-1.0, 2147483392 / 2**31)),
        ("<f4", (-1.0, 1.0)),
    ])
    def test_rails_are_the_extreme_codes(self, dtype, rails):
        layout = wav.WavLayout(44100.0, 2, 2 * np.dtype(dtype).itemsize, np.dtype(dtype).itemsize, np.dtype(dtype), 44, 0)
        assert wav.full_scale_rails(layout) == rails


class TestDecode:
    def test_24_bit_samples_are_left_justified_in_32_bits_in_either_byte_order(self):
        codes = np.array([[-8388608, 8388607], [1, -1]])
        little = codes.astype("<i4").view(np.uint8).reshape(2, 2, 4)[..., :3].reshape(2, 6)
        big = codes.astype(">i4").view(np.uint8).reshape(2, 2, 4)[..., 1:].reshape(2, 6)
        for order, frames in (("<", little), (">", big)):
            layout = wav.WavLayout(44100.0, 2, 6, 3, np.dtype(order + "i4"), 44, 2)
            for channel in (0, 1):
                np.testing.assert_array_equal(wav.decode(frames, layout, channel), codes[:, channel] * 256)

    def test_padded_frames_give_each_channel(self):
        # Three channels of 16 bits in frames of 8 bytes (2 bytes of padding).
        codes = np.array([[1, -2, 3, 0], [4, -5, 6, 0]], dtype="<i2")
        layout = wav.WavLayout(44100.0, 3, 8, 2, np.dtype("<i2"), 44, 2)
        frames = codes.view(np.uint8).reshape(2, 8)
        np.testing.assert_array_equal(wav.decode(frames, layout, 1), [-2, -5])


class TestWrite:
    def test_blocks_write_the_same_file_as_the_whole(self, tmp_path, rng):
        u, y = 0.3 * rng.standard_normal(1000), np.clip(0.5 * rng.standard_normal(1000), -1.2, 1.2)
        wav.write_wav16(tmp_path / "whole.wav", u, y, 44100)
        frames = wav.write_wav16_blocks(tmp_path / "blocks.wav", [(u[:300], y[:300]), (u[300:], y[300:])], 44100)
        assert frames == 1000
        whole, blocks = (scipy.io.wavfile.read(tmp_path / name)[1] for name in ("whole.wav", "blocks.wav"))
        np.testing.assert_array_equal(whole, blocks)

    def test_rounds_and_saturates(self, tmp_path):
        wav.write_wav16(tmp_path / "a.wav", np.array([0.5 / 32768, -2.0]), np.array([1.0, 1.5 / 32768]), 44100)
        layout, frames = _frames(tmp_path / "a.wav")
        np.testing.assert_array_equal(wav.decode(frames, layout, 0), [0, -32768])
        np.testing.assert_array_equal(wav.decode(frames, layout, 1), [32767, 2])


def test_frames_of_a_file_cut_short_after_its_header_was_read_are_a_one_line_error(tmp_path):
    wav.write_wav16(tmp_path / "a.wav", np.zeros(100), np.zeros(100), 44100)
    layout = wav.read_layout(tmp_path / "a.wav")
    with open(tmp_path / "a.wav", "r+b") as handle:
        handle.truncate(200)
    with pytest.raises(RecordingError, match="a.wav: the file is shorter than when it was opened; open it again"):
        wav.read_frames(str(tmp_path / "a.wav"), layout, 0, 100)
