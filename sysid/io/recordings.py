"""Stereo WAV recordings of one sound path, read and checked against the input contract.

Channel 0 is the path input (headphone drive voltage for FB, chin microphone for FF)
and channel 1 the ear-canal microphone, unless overridden. Samples are scaled to
full-scale units in [-1, 1): 16-bit PCM by 2^-15, 24/32-bit PCM (24-bit left-justified
in 32 bits, as scipy.io.wavfile returns it) by 2^-31, 8-bit unsigned PCM by
(x - 128)/128, float as is.

Two ways in, one reader and one set of checks:

* ``open_recording`` returns a ``RecordingFile``: it holds no samples and reads blocks
  of them from the file's data chunk when asked (``read``, windows by ``trimmed`` and
  ``advanced``, a first part in memory by ``head``), so ``sysid.identify`` handles a
  recording of any length in bounded memory.
* ``load_recording`` is ``open_recording(...).load()``: both channels in memory as a
  ``Recording``, for everything that works on whole signals (compare, diagnose, report).

Anything unusable raises RecordingError with a one-line message naming the file. The
checks run block by block over the whole file (``QUALITY_BLOCK`` samples at a time):
NaN/inf, silent input, silent or unrelated ear channel. Clipping and a DC offset are
reported (a RecordingWarning and the fields ``clipped_fraction`` and ``dc_offset``)
because the diagnosis explains them; ``sysid.io.data_quality`` judges each block, and a
recording longer than one block gets the total clipped fraction and the median of the
blocks' offsets (significant when the blocks that find one hold most of the samples).
"""

from __future__ import annotations

import struct
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import scipy.io.wavfile

from ..core.errors import RecordingError
from .data_quality import clipped_samples, dc_offset

__all__ = ["Recording", "RecordingFile", "RecordingWarning", "WavLayout", "read_layout", "open_recording",
           "load_recording", "check_same_rate", "write_wav16", "write_wav16_blocks", "recording_from_arrays",
           "QUALITY_BLOCK"]


class RecordingWarning(UserWarning):
    """A recording is usable but has a data-quality problem (clipping, DC offset)."""


@dataclass
class Recording:
    """One stereo recording in memory: input u and ear signal y in full-scale units at fs Hz."""

    u: np.ndarray
    y: np.ndarray
    fs: float
    path: str = "<array>"
    clipped_fraction: tuple[float, float] = (0.0, 0.0)
    dc_offset: tuple[float, float] = (0.0, 0.0)

    @property
    def duration(self) -> float:
        return self.u.size / self.fs

    @property
    def length(self) -> int:
        """Number of samples per channel."""
        return self.u.size

    def read(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """Samples start..stop-1 of (u, y), as ``RecordingFile.read``."""
        return self.u[start:stop], self.y[start:stop]

    def blocks(self, size: int):
        """(u, y) blocks of ``size`` samples (the last one shorter), as ``RecordingFile.blocks``."""
        return _blocks(self, size)

    def trimmed(self, start_s: float) -> "Recording":
        """The recording without its first start_s seconds (e.g. the 3 s noise transient)."""
        first = int(round(start_s * self.fs))
        return Recording(self.u[first:], self.y[first:], self.fs, self.path, self.clipped_fraction, self.dc_offset)

    def head(self, seconds: float | None) -> "Recording":
        """The first ``seconds`` (all of it for None), as ``RecordingFile.head``."""
        return _head(self, seconds)


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


@dataclass(frozen=True)
class RecordingFile:
    """A stereo recording read from its WAV file in blocks: u and y in full-scale units at fs Hz.

    Sample k of u is frame ``first + k`` of the file and sample k of y frame
    ``first + lag + k``; ``length`` samples per channel. Nothing is cached: each
    ``read`` reads the file.
    """

    path: str
    fs: float
    length: int
    layout: WavLayout
    input_channel: int
    output_channel: int
    first: int = 0
    lag: int = 0
    clipped_fraction: tuple[float, float] = (0.0, 0.0)
    dc_offset: tuple[float, float] = (0.0, 0.0)

    @property
    def duration(self) -> float:
        return self.length / self.fs

    def read(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """Samples start..stop-1 (clipped to 0..length) of u and y as float64 arrays."""
        start, stop = max(int(start), 0), min(int(stop), self.length)
        n = max(stop - start, 0)
        frames = _read_frames(self.path, self.layout, self.first + start, self.first + self.lag + start + n)
        u = _full_scale(_decode(frames[:n], self.layout, self.input_channel))
        y = _full_scale(_decode(frames[self.lag:self.lag + n], self.layout, self.output_channel))
        return u, y

    def blocks(self, size: int):
        """(u, y) blocks of ``size`` samples (the last one shorter), each read when the iteration reaches it."""
        return _blocks(self, size)

    def trimmed(self, start_s: float) -> "RecordingFile":
        """The recording without its first start_s seconds (as ``Recording.trimmed``)."""
        skip = min(int(round(start_s * self.fs)), self.length)
        return replace(self, first=self.first + skip, length=self.length - skip)

    def advanced(self, samples: int) -> "RecordingFile":
        """u[t] against y[t + samples]: ``sysid.estimation.delay.compensate_delay`` for a recording read from its file."""
        if samples <= 0:
            return self
        samples = min(int(samples), self.length)
        return replace(self, lag=self.lag + samples, length=self.length - samples)

    def head(self, seconds: float | None) -> Recording:
        """The first ``seconds`` (all of it for None) in memory, as a Recording."""
        return _head(self, seconds)

    def load(self) -> Recording:
        """All samples in memory (8 bytes per sample and channel), as a Recording."""
        return self.head(None)


def _head(recording: Recording | RecordingFile, seconds: float | None) -> Recording:
    n = recording.length if seconds is None else min(recording.length, int(round(seconds * recording.fs)))
    u, y = recording.read(0, n)
    return Recording(u, y, recording.fs, recording.path, recording.clipped_fraction, recording.dc_offset)


def _blocks(recording: Recording | RecordingFile, size: int):
    for start in range(0, recording.length, int(size)):
        yield recording.read(start, start + int(size))


_PCM, _IEEE_FLOAT, _EXTENSIBLE = 0x0001, 0x0003, 0xFFFE
# Scaling per decoded sample type: (code offset, divisor, highest code); the rails are -1 and the highest code.
_SCALING = {np.dtype(np.uint8): (128.0, 128.0, 255), np.dtype(np.int16): (0.0, 32768.0, 32767),
            np.dtype(np.int32): (0.0, 2147483648.0, 2147483392)}


def _unreadable(name: str, reason: str) -> RecordingError:
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
            raise _unreadable(name, "no RIFF/WAVE header")
        order = "<" if header[:4] == b"RIFF" else ">"
        position = 12
        while position + 8 <= size:
            handle.seek(position)
            chunk_id, chunk_size = struct.unpack(order + "4sI", handle.read(8))
            if chunk_id == b"fmt ":
                raw = handle.read(min(chunk_size, 40))
                if len(raw) < 16:
                    raise _unreadable(name, f"fmt chunk of {len(raw)} bytes, expected at least 16")
                fmt = struct.unpack(order + "HHIIHH", raw[:16])
                if fmt[0] == _EXTENSIBLE and len(raw) >= 26:
                    # WAVE_FORMAT_EXTENSIBLE: the format code is the first two bytes of the sub-format GUID.
                    fmt = (struct.unpack(order + "H", raw[24:26])[0], *fmt[1:])
            elif chunk_id == b"data":
                if fmt is None:
                    raise _unreadable(name, "data chunk before the fmt chunk")
                return _layout(name, fmt, order, position + 8, min(chunk_size, size - position - 8))
            position += 8 + chunk_size + (chunk_size & 1)
    raise _unreadable(name, "no fmt chunk" if fmt is None else "no data chunk")


def _layout(name: str, fmt: tuple, order: str, offset: int, size: int) -> WavLayout:
    tag, channels, rate, _, block_align, bits = fmt
    if channels == 0:
        raise _unreadable(name, "0 channels")
    if channels == 1:
        raise RecordingError(f"{name}: mono file; expected 2 channels (input, ear microphone)")
    sample_bytes = block_align // channels
    if sample_bytes == 0:
        raise _unreadable(name, f"{block_align} bytes per frame for {channels} channels")
    if tag == _PCM and 0 < bits <= 8:
        kind = "u1" if sample_bytes == 1 else None
    elif tag == _PCM:
        kind = {2: "i2", 3: "i4", 4: "i4"}.get(sample_bytes)  # 24-bit is decoded to int32 (_decode)
    elif tag == _IEEE_FLOAT:
        kind = {4: "f4", 8: "f8"}.get(sample_bytes) if bits in (32, 64) else None
    else:
        raise _unreadable(name, f"format code 0x{tag:04x} is neither PCM nor IEEE float")
    if kind is None:
        family = "integer" if tag == _PCM else "float"
        raise RecordingError(f"{name}: unsupported sample format ({bits}-bit {family} in {sample_bytes}-byte samples); "
                             "use 8, 16, 24 or 32-bit PCM or 32/64-bit float")
    if rate == 0:
        raise RecordingError(f"{name}: sample rate must be positive; found 0")
    return WavLayout(float(rate), channels, block_align, sample_bytes, np.dtype(order + kind), offset, size // block_align)


def _read_frames(path: str, layout: WavLayout, start: int, stop: int) -> np.ndarray:
    """Frames start..stop-1 as raw bytes, shape (frames, block_align); read, never memory-mapped."""
    count = max(stop - start, 0)
    with open(path, "rb") as handle:
        handle.seek(layout.data_offset + start * layout.block_align)
        raw = np.fromfile(handle, np.uint8, count * layout.block_align)
    if raw.size != count * layout.block_align:
        raise RecordingError(f"{path}: the file is shorter than when it was opened; open it again")
    return raw.reshape(count, layout.block_align)


def _decode(frames: np.ndarray, layout: WavLayout, channel: int) -> np.ndarray:
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


def _full_scale(data: np.ndarray) -> np.ndarray:
    """Decoded samples in full-scale units [-1, 1) (see the module docstring)."""
    if data.dtype.kind == "f":
        return data.astype(float)
    offset, divisor, _ = _SCALING[data.dtype]
    return (data.astype(float) - offset) / divisor if offset else data / divisor


def _rails(layout: WavLayout) -> tuple[float, float]:
    """The lowest and highest full-scale value the format can hold."""
    if layout.dtype.kind == "f":
        return -1.0, 1.0
    offset, divisor, highest = _SCALING[layout.dtype.newbyteorder("=")]
    return -1.0, (highest - offset) / divisor


@dataclass
class _Scan:
    """What one pass over a recording found: ear-channel energy and the data-quality figures."""

    length: int = 0
    y_energy: float = 0.0
    clipped: tuple[float, float] = (0.0, 0.0)
    offsets: tuple[float, float] = (0.0, 0.0)
    significant: tuple[bool, bool] = (False, False)


def _scan(name: str, blocks, rails: tuple[float, float]) -> _Scan:
    """Sample checks and data quality of (u, y) blocks, one pass (see the module docstring)."""
    length, energy, any_input = 0, 0.0, False
    clipped = np.zeros(2)
    offsets: list[list[float]] = [[], []]
    flagged = np.zeros(2)
    sizes = []
    for u, y in blocks:
        for label, x in (("input", u), ("output", y)):
            if not np.all(np.isfinite(x)):
                raise RecordingError(f"{name}: {label} channel has NaN or infinite samples")
        if u.size == 0:
            continue
        length += u.size
        any_input = any_input or bool(np.any(u))
        energy += float(np.dot(y, y))
        sizes.append(u.size)
        for k, x in enumerate((u, y)):
            # One clipping and one DC algorithm for loader, diagnosis and refine (sysid.io.data_quality).
            clipped[k] += np.count_nonzero(clipped_samples(x, rails).mask)
            offset, significant = dc_offset(x)
            offsets[k].append(offset)
            flagged[k] += u.size if significant else 0
    if length == 0:
        raise RecordingError(f"{name}: recording has no samples")
    if not any_input:
        raise RecordingError(f"{name}: input channel is silent (all samples zero)")
    significant = tuple(bool(f > length / 2) for f in flagged)
    median = tuple(float(np.median(o)) if len(o) > 1 else o[0] for o in offsets)
    return _Scan(length, energy, tuple(float(c / length) for c in clipped),
                 tuple(m if s else 0.0 for m, s in zip(median, significant)), significant)


def _warn_quality(name: str, scan: _Scan) -> None:
    for label, fraction, offset in zip(("input", "output"), scan.clipped, scan.offsets):
        if fraction:
            warnings.warn(f"{name}: {label} channel clipped on {100 * fraction:.3g} % of samples", RecordingWarning,
                          stacklevel=4)
        if offset:
            warnings.warn(f"{name}: {label} channel has a DC offset of {offset:.3g} FS", RecordingWarning, stacklevel=4)


def open_recording(path, input_channel: int = 0, output_channel: int = 1) -> RecordingFile:
    """A stereo WAV file as a RecordingFile: header and every check of the contract, no samples kept.

    Reads the file block by block once for the checks and the data quality, and again
    for the ear channel's coherence with the input (``sysid.estimation.spectra.streamed_spectra``).
    """
    name = str(path)
    if Path(path).is_dir():
        raise RecordingError(f"{name}: is a folder; give a WAV file")
    if not Path(path).is_file():
        raise RecordingError(f"{name}: no such file")
    size = Path(path).stat().st_size
    if size > MAX_RECORDING_BYTES:
        raise RecordingError(f"{name}: {size / 2**30:.1f} GiB is above the limit of {MAX_RECORDING_BYTES / 2**30:.0f} "
                             "GiB per recording (3 h of 16-bit stereo at 44.1 kHz); cut it into shorter recordings")
    try:
        layout = read_layout(path, name)
    except OSError as exc:
        raise _unreadable(name, exc.strerror or type(exc).__name__) from None
    for label, index in (("input", input_channel), ("output", output_channel)):
        if not 0 <= index < layout.channels:
            raise RecordingError(f"{name}: {label} channel {index} does not exist (file has {layout.channels} channels)")
    if input_channel == output_channel:
        raise RecordingError(f"{name}: input and output channel are both {input_channel}")
    recording = RecordingFile(name, layout.fs, layout.frames, layout, input_channel, output_channel)
    scan = _scan(name, recording.blocks(QUALITY_BLOCK), _rails(layout))
    _check_ear_channel(recording, scan)
    _warn_quality(name, scan)
    return replace(recording, clipped_fraction=scan.clipped, dc_offset=scan.offsets)


def load_recording(path, input_channel: int = 0, output_channel: int = 1) -> Recording:
    """Load a stereo WAV file as a Recording in memory (``open_recording`` then ``load``)."""
    return open_recording(path, input_channel, output_channel).load()


# Reading holds a block of QUALITY_BLOCK samples per channel as float64 plus the quality
# algorithms' temporaries (about 50 MB); 2^21 samples are 47.5 s at 44.1 kHz, so sessions of
# the usual length are judged in one block.
QUALITY_BLOCK = 2**21
# Loading holds the samples as float64 (4x a 16-bit file): 2 GiB of WAV is 8 GiB of memory.
# open_recording, which holds none, keeps the same limit so that both ways in accept the same files.
MAX_RECORDING_BYTES = 2 * 2**30
# An ear channel below half a 16-bit LSB (RMS) is digital silence: nothing is connected.
SILENT_RMS = 2.0**-16
# Median magnitude-squared coherence between input and ear channel, 100 Hz - 4 kHz, below which
# the ear microphone does not hear the path at all. It is estimated on stretches short enough
# that an ear clock off by up to a few hundred ppm (effects.md, clock drift) slips by no more than
# a few samples inside one: over a whole recording such a slip turns the cross-spectrum's phase
# and the averaged coherence of a healthy channel collapses above a few hundred Hz (60 ppm over
# 20 s: median 0.01). A sweep, whose every frequency is excited only briefly, is judged over the
# whole recording instead (a stretch of it excites a few bins only): the larger of the two counts.
UNCORRELATED_COHERENCE = 0.1
_COHERENCE_SEGMENT = 512
_COHERENCE_STRETCH = 32 * _COHERENCE_SEGMENT
_COHERENCE_STRETCHES = 8


def _check_ear_channel(recording: RecordingFile, scan: _Scan) -> None:
    """RecordingError for an ear channel that is silent or does not hear the input (disconnected, wrong channel)."""
    name, fs = recording.path, recording.fs
    fix = "check the microphone, or choose the channels with --input-channel/--output-channel"
    if np.sqrt(scan.y_energy / scan.length) < SILENT_RMS:
        raise RecordingError(f"{name}: ear channel {recording.output_channel} is silent (disconnected microphone?); {fix}")
    coherence = ear_coherence(recording)
    if coherence is not None and coherence < UNCORRELATED_COHERENCE:
        raise RecordingError(f"{name}: ear channel {recording.output_channel} does not follow input channel "
                             f"{recording.input_channel} (median coherence {coherence:.2f}); {fix}")


def ear_coherence(recording) -> float | None:
    """Median coherence (Welch, Hann, ``_COHERENCE_SEGMENT``-sample segments) of input and ear
    channel in 100 Hz - 4 kHz: the larger of its value over the whole recording and the median
    over up to ``_COHERENCE_STRETCHES`` stretches of ``_COHERENCE_STRETCH`` samples spread over
    it (each stretch's own median); None for a recording shorter than one stretch."""
    from ..estimation.spectra import response, streamed_spectra  # spectra builds on this module

    count = min(recording.length // _COHERENCE_STRETCH, _COHERENCE_STRETCHES)
    if count < 1:
        return None
    band = (100.0, min(4000.0, 0.45 * recording.fs))

    def median_coherence(read, length):
        spectra = streamed_spectra(read, length, recording.fs, _COHERENCE_SEGMENT, recording.path)
        coherence = response(spectra, band).coherence
        return float(np.median(coherence)) if coherence.size else np.nan

    whole = median_coherence(recording.read, recording.length)
    stretches = [median_coherence(lambda a, b, start=start: recording.read(start + a, start + b), _COHERENCE_STRETCH)
                 for start in np.linspace(0, recording.length - _COHERENCE_STRETCH, count).astype(int)]
    values = [v for v in (whole, float(np.nanmedian(stretches)) if np.any(np.isfinite(stretches)) else np.nan)
              if np.isfinite(v)]
    return max(values) if values else None


def recording_from_arrays(u, y, fs: float, name: str = "<array>") -> Recording:
    """A Recording from numpy arrays (full-scale units), with the same sample checks as a file."""
    u = np.asarray(u, dtype=float).reshape(-1)
    y = np.asarray(y, dtype=float).reshape(-1)
    if u.size != y.size:
        raise RecordingError(f"{name}: input has {u.size} samples but output has {y.size}")
    if not (np.isfinite(fs) and fs > 0):
        raise RecordingError(f"{name}: sample rate must be positive; found {fs}")
    scan = _scan(name, [(u, y)], (-1.0, 32767 / 32768.0))
    _warn_quality(name, scan)
    return Recording(u, y, float(fs), name, scan.clipped, scan.offsets)


def check_same_rate(recordings) -> float:
    """The common sample rate of the recordings; a mismatch is an error, never a resample."""
    recordings = list(recordings)
    fs = recordings[0].fs
    for recording in recordings[1:]:
        if recording.fs != fs:
            raise RecordingError(
                f"{recording.path}: sample rate {recording.fs:g} Hz differs from {fs:g} Hz of {recordings[0].path}"
            )
    return fs


def _pcm16(u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Interleaved 16-bit PCM frames (channel 0 = u, channel 1 = y), rounded and saturated."""
    stereo = np.stack([u, y], axis=1) * 32768.0
    return np.clip(np.round(stereo), -32768, 32767).astype(np.int16)


def write_wav16(path, u: np.ndarray, y: np.ndarray, fs: float) -> None:
    """Write a stereo 16-bit PCM WAV (channel 0 = u, channel 1 = y), rounding and saturating."""
    scipy.io.wavfile.write(path, int(round(fs)), _pcm16(u, y))


def write_wav16_blocks(path, blocks, fs: float) -> int:
    """Write a stereo 16-bit PCM WAV from an iterable of (u, y) blocks, one block in memory at a time.

    Same samples as ``write_wav16`` on the blocks joined; for recordings too long to hold
    (up to ``MAX_RECORDING_BYTES``). Returns the number of frames written.
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
