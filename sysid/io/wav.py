"""WAV files: the header, the sample formats and their scaling to full scale; stereo written in each format.

``read_layout`` walks a file's chunks (RIFF or RIFX, PCM or IEEE float, plain or
WAVE_FORMAT_EXTENSIBLE) to where its frames are; ``read_frames`` reads a run of frames
as raw bytes, ``decode`` takes one channel out of them and ``full_scale`` scales it to
full-scale units in [-1, 1): 16-bit PCM by 2^-15, 24/32-bit PCM (24-bit left-justified
in 32 bits, as scipy.io.wavfile returns it) by 2^-31, 8-bit unsigned PCM by
(x - 128)/128, float as is. ``sysid.io.recordings`` builds its recordings on these;
``write_wav`` writes stereo 16, 24 or 32-bit PCM or 32-bit float (``SAMPLE_FORMATS``; what
``sysid.simulate`` records, the inverse of that scaling, so a written file reads back to the
same samples), ``write_wav16_blocks`` 16-bit PCM from blocks. A file that is no readable WAV raises RecordingError with a one-line message
naming it.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.io.wavfile

from ..core.errors import RecordingError

__all__ = ["WavLayout", "read_layout", "read_frames", "decode", "full_scale", "full_scale_rails", "unreadable",
           "write_wav16", "write_wav16_blocks", "write_wav", "quantise", "SAMPLE_FORMATS"]

# The sample formats written: PCM of 16, 24 or 32 bits, or IEEE float of 32 bits.
SAMPLE_FORMATS = ("16", "24", "32", "float")


@dataclass(frozen=True)
class WavLayout:
    """Where a WAV file keeps its samples: ``frames`` interleaved frames of ``channels`` samples.

    ``data_offset`` is the byte offset of the first frame, ``block_align`` the bytes per
    frame, ``sample_bytes`` the bytes per sample and ``dtype`` what a sample decodes to
    (uint8, int16, int32 for 24 and 32-bit PCM, float32 or float64), in file byte order.
    """

    fs: float
    channels: int
    block_align: int
    sample_bytes: int
    dtype: np.dtype
    data_offset: int
    frames: int


_PCM, _IEEE_FLOAT, _EXTENSIBLE = 0x0001, 0x0003, 0xFFFE
# Scaling per decoded sample type: (code offset, divisor, highest code); the rails are -1 and the highest code.
_SCALING = {np.dtype(np.uint8): (128.0, 128.0, 255), np.dtype(np.int16): (0.0, 32768.0, 32767),
            np.dtype(np.int32): (0.0, 2147483648.0, 2147483392)}


def unreadable(name: str, reason: str) -> RecordingError:
    """The one-line error of a file ``name`` that is no readable WAV file, for ``reason``."""
    return RecordingError(f"{name}: not a readable WAV file ({reason})")


def read_layout(path, name: str | None = None) -> WavLayout:
    """The WAV header of ``path``: format, channels, rate and where the frames are (RIFF or RIFX).

    Walks the chunks (fmt, data, anything else skipped with its pad byte); a data chunk
    longer than the file is cut to whole frames of what is there.
    """
    name = str(path) if name is None else name
    size = Path(path).stat().st_size
    fmt = None
    with open(path, "rb") as handle:
        header = handle.read(12)
        if len(header) < 12 or header[:4] not in (b"RIFF", b"RIFX") or header[8:12] != b"WAVE":
            raise unreadable(name, "no RIFF/WAVE header")
        order = "<" if header[:4] == b"RIFF" else ">"
        position = 12
        while position + 8 <= size:
            handle.seek(position)
            chunk_id, chunk_size = struct.unpack(order + "4sI", handle.read(8))
            if chunk_id == b"fmt ":
                raw = handle.read(min(chunk_size, 40))
                if len(raw) < 16:
                    raise unreadable(name, f"fmt chunk of {len(raw)} bytes, expected at least 16")
                fmt = struct.unpack(order + "HHIIHH", raw[:16])
                if fmt[0] == _EXTENSIBLE and len(raw) >= 26:
                    # WAVE_FORMAT_EXTENSIBLE: the format code is the first two bytes of the sub-format GUID.
                    fmt = (struct.unpack(order + "H", raw[24:26])[0], *fmt[1:])
            elif chunk_id == b"data":
                if fmt is None:
                    raise unreadable(name, "data chunk before the fmt chunk")
                return _layout(name, fmt, order, position + 8, min(chunk_size, size - position - 8))
            position += 8 + chunk_size + (chunk_size & 1)
    raise unreadable(name, "no fmt chunk" if fmt is None else "no data chunk")


def _layout(name: str, fmt: tuple, order: str, offset: int, size: int) -> WavLayout:
    tag, channels, rate, _, block_align, bits = fmt
    if channels == 0:
        raise unreadable(name, "0 channels")
    if channels == 1:
        raise RecordingError(f"{name}: mono file; expected 2 channels (input, ear microphone)")
    sample_bytes = block_align // channels
    if sample_bytes == 0:
        raise unreadable(name, f"{block_align} bytes per frame for {channels} channels")
    if tag == _PCM and 0 < bits <= 8:
        kind = "u1" if sample_bytes == 1 else None
    elif tag == _PCM:
        kind = {2: "i2", 3: "i4", 4: "i4"}.get(sample_bytes)  # 24-bit is decoded to int32 (decode)
    elif tag == _IEEE_FLOAT:
        kind = {4: "f4", 8: "f8"}.get(sample_bytes) if bits in (32, 64) else None
    else:
        raise unreadable(name, f"format code 0x{tag:04x} is neither PCM nor IEEE float")
    if kind is None:
        family = "integer" if tag == _PCM else "float"
        raise RecordingError(f"{name}: unsupported sample format ({bits}-bit {family} in {sample_bytes}-byte samples); "
                             "use 8, 16, 24 or 32-bit PCM or 32/64-bit float")
    if rate == 0:
        raise RecordingError(f"{name}: sample rate must be positive; found 0")
    return WavLayout(float(rate), channels, block_align, sample_bytes, np.dtype(order + kind), offset, size // block_align)


def read_frames(path: str, layout: WavLayout, start: int, stop: int) -> np.ndarray:
    """Frames start..stop-1 as raw bytes, shape (frames, block_align); read, never memory-mapped."""
    count = max(stop - start, 0)
    with open(path, "rb") as handle:
        handle.seek(layout.data_offset + start * layout.block_align)
        raw = np.fromfile(handle, np.uint8, count * layout.block_align)
    if raw.size != count * layout.block_align:
        raise RecordingError(f"{path}: the file is shorter than when it was opened; open it again")
    return raw.reshape(count, layout.block_align)


def decode(frames: np.ndarray, layout: WavLayout, channel: int) -> np.ndarray:
    """One channel of raw frames as native uint8, int16, int32 (24-bit left-justified) or float samples."""
    width = layout.sample_bytes
    raw = frames[:, channel * width:(channel + 1) * width]
    if width == 3:
        b = raw.astype(np.uint32)
        low, high = (b[:, 0], b[:, 2]) if layout.dtype.byteorder != ">" else (b[:, 2], b[:, 0])
        return ((high << 24) | (b[:, 1] << 16) | (low << 8)).view(np.int32)
    if layout.block_align == layout.channels * width:
        # Frames without padding: a strided view of the block, copied once by the scaling.
        samples = frames.view(layout.dtype)[:, channel]
    else:
        samples = np.ascontiguousarray(raw).view(layout.dtype).reshape(-1)
    return samples.astype(layout.dtype.newbyteorder("="), copy=False)


def full_scale(data: np.ndarray) -> np.ndarray:
    """Decoded samples (``decode``) in full-scale units [-1, 1) (see the module docstring)."""
    if data.dtype.kind == "f":
        return data.astype(float)
    offset, divisor, _ = _SCALING[data.dtype]
    return (data.astype(float) - offset) / divisor if offset else data / divisor


def full_scale_rails(layout: WavLayout) -> tuple[float, float]:
    """The lowest and highest full-scale value the format can hold."""
    if layout.dtype.kind == "f":
        return -1.0, 1.0
    offset, divisor, highest = _SCALING[layout.dtype.newbyteorder("=")]
    return -1.0, (highest - offset) / divisor


def _pcm16(u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Interleaved 16-bit PCM frames (channel 0 = u, channel 1 = y), rounded and saturated."""
    stereo = np.stack([u, y], axis=1) * 32768.0
    return np.clip(np.round(stereo), -32768, 32767).astype(np.int16)


def write_wav16(path, u: np.ndarray, y: np.ndarray, fs: float) -> None:
    """Write a stereo 16-bit PCM WAV (channel 0 = u, channel 1 = y), rounding and saturating."""
    scipy.io.wavfile.write(path, int(round(fs)), _pcm16(u, y))


def _sample_format(bits) -> str:
    text = str(bits)
    if text not in SAMPLE_FORMATS:
        raise RecordingError(f"sample format must be one of {', '.join(SAMPLE_FORMATS)} (bits of PCM, or float); "
                             f"found {bits!r}")
    return text


def quantise(x: np.ndarray, bits="16") -> np.ndarray:
    """x (full-scale units) as a file of ``bits`` holds it: PCM codes rounded and saturated at
    [-1, 1 - 2^(1-bits)], scaled back; float rounded to float32."""
    bits = _sample_format(bits)
    if bits == "float":
        return np.asarray(x, dtype=np.float32).astype(float)
    scale = 2.0 ** (int(bits) - 1)
    return np.clip(np.round(np.asarray(x, float) * scale), -scale, scale - 1) / scale


def write_wav(path, u: np.ndarray, y: np.ndarray, fs: float, bits="16") -> None:
    """Write a stereo WAV (channel 0 = u, channel 1 = y) of ``bits`` (``SAMPLE_FORMATS``): PCM rounded and
    saturated, 24-bit packed in 3 bytes; float as IEEE float32 (with the fact chunk non-PCM formats carry)."""
    bits = _sample_format(bits)
    rate = int(round(fs))
    stereo = np.stack([np.asarray(u, float), np.asarray(y, float)], axis=1)
    if bits == "float":
        data, tag, width = stereo.astype("<f4").tobytes(), _IEEE_FLOAT, 4
    else:
        width = int(bits) // 8
        scale = 2.0 ** (int(bits) - 1)
        codes = np.clip(np.round(stereo * scale), -scale, scale - 1).astype("<i4")
        if width == 2:
            data = codes.astype("<i2").tobytes()
        elif width == 3:
            # The three low bytes of each little-endian int32: packed 24-bit samples.
            data = codes.view(np.uint8).reshape(-1, 4)[:, :3].tobytes()
        else:
            data = codes.tobytes()
        tag = _PCM
    frames = stereo.shape[0]
    fmt = struct.pack("<HHIIHH", tag, 2, rate, 2 * width * rate, 2 * width, 8 * width)
    chunks = b"fmt " + struct.pack("<I", len(fmt)) + fmt
    if tag == _IEEE_FLOAT:
        fmt = fmt + struct.pack("<H", 0)
        chunks = b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"fact" + struct.pack("<II", 4, frames)
    body = chunks + b"data" + struct.pack("<I", len(data)) + data + (b"\0" if len(data) & 1 else b"")
    with open(path, "wb") as handle:
        handle.write(b"RIFF" + struct.pack("<I", 4 + len(body)) + b"WAVE" + body)


def write_wav16_blocks(path, blocks, fs: float) -> int:
    """Write a stereo 16-bit PCM WAV from an iterable of (u, y) blocks, one block in memory at a time.

    Same samples as ``write_wav16`` on the blocks joined; for recordings too long to hold
    (up to ``sysid.io.recordings.MAX_RECORDING_BYTES``). Returns the number of frames written.
    """
    rate = int(round(fs))

    def header(frames: int) -> bytes:
        data = 4 * frames
        return (b"RIFF" + struct.pack("<I", 36 + data) + b"WAVE" + b"fmt " + struct.pack("<IHHIIHH", 16, _PCM, 2, rate,
                4 * rate, 4, 16) + b"data" + struct.pack("<I", data))

    frames = 0
    with open(path, "wb") as handle:
        handle.write(header(0))
        for u, y in blocks:
            handle.write(_pcm16(np.asarray(u, float), np.asarray(y, float)).astype("<i2").tobytes())
            frames += len(u)
        handle.seek(0)
        handle.write(header(frames))
    return frames
