"""Stereo recordings of one sound path, read and checked against the input contract.

Channel 0 is the path input (headphone drive voltage for FB, chin microphone for FF)
and channel 1 the ear-canal microphone, unless overridden. Samples are in full-scale
units in [-1, 1) (``sysid.io.wav`` decodes and scales every sample format).

Two ways in, one reader and one set of checks:

* ``open_recording`` returns a ``RecordingFile``: it holds no samples and reads blocks
  of them from the file's data chunk when asked (``read``, windows by ``trimmed`` and
  ``advanced``, a first part in memory by ``head``), so ``sysid.identify`` handles a
  recording of any length in bounded memory.
* ``load_recording`` is ``open_recording(...).load()``: both channels in memory as a
  ``Recording``, for everything that works on whole signals (compare, diagnose, report).

Anything unusable raises RecordingError with a one-line message naming the file. The
checks run block by block over the whole file (``QUALITY_BLOCK`` samples at a time):
NaN/inf and silent input here, a silent or unrelated ear channel in
``sysid.io.ear_channel``. Clipping and a DC offset are reported (a RecordingWarning and
the fields ``clipped_fraction`` and ``dc_offset``) because the diagnosis explains them;
``sysid.io.data_quality`` judges each block, and a recording longer than one block gets
the total clipped fraction and the median of the blocks' offsets (significant when the
blocks that find one hold most of the samples).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..core.errors import RecordingError
# Also imported from here, where they were defined before the WAV decoding and the ear-channel
# checks had modules of their own: SILENT_RMS, UNCORRELATED_COHERENCE, ear_coherence, read_layout, WavLayout,
# write_wav16, write_wav16_blocks.
from ..core.thresholds import SILENT_RMS, UNCORRELATED_COHERENCE  # noqa: F401
from ..core.thresholds import NOISE_AFTER_TRANSIENT_S, TRANSIENT_S
from . import wav
from .data_quality import clipped_samples, dc_offset
from .ear_channel import check_ear_channel, ear_coherence  # noqa: F401
from .wav import WavLayout, read_layout, write_wav16, write_wav16_blocks  # noqa: F401

__all__ = ["Recording", "RecordingFile", "RecordingWarning", "WavLayout", "read_layout", "open_recording",
           "load_recording", "check_same_rate", "check_noise_length", "noise_length_rule", "write_wav16", "write_wav16_blocks", "recording_from_arrays",
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
        frames = wav.read_frames(self.path, self.layout, self.first + start, self.first + self.lag + start + n)
        u = wav.full_scale(wav.decode(frames[:n], self.layout, self.input_channel))
        y = wav.full_scale(wav.decode(frames[self.lag:self.lag + n], self.layout, self.output_channel))
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


# Reading holds a block of QUALITY_BLOCK samples per channel as float64 plus the quality
# algorithms' temporaries (about 50 MB); 2^21 samples are 47.5 s at 44.1 kHz, so sessions of
# the usual length are judged in one block.
QUALITY_BLOCK = 2**21
# Loading holds the samples as float64 (4x a 16-bit file): 2 GiB of WAV is 8 GiB of memory.
# open_recording, which holds none, keeps the same limit so that both ways in accept the same files.
MAX_RECORDING_BYTES = 2 * 2**30


def open_recording(path, input_channel: int = 0, output_channel: int = 1) -> RecordingFile:
    """A stereo WAV file as a RecordingFile: header and every check of the contract, no samples kept.

    Reads the file block by block once for the checks and the data quality, and again
    for the ear channel's coherence with the input (``sysid.io.ear_channel``).
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
        raise wav.unreadable(name, exc.strerror or type(exc).__name__) from None
    for label, index in (("input", input_channel), ("output", output_channel)):
        if not 0 <= index < layout.channels:
            raise RecordingError(f"{name}: {label} channel {index} does not exist (file has {layout.channels} channels)")
    if input_channel == output_channel:
        raise RecordingError(f"{name}: input and output channel are both {input_channel}")
    recording = RecordingFile(name, layout.fs, layout.frames, layout, input_channel, output_channel)
    scan = _scan(name, recording.blocks(QUALITY_BLOCK), wav.full_scale_rails(layout))
    check_ear_channel(recording, scan.y_energy, scan.length)
    _warn_quality(name, scan)
    return replace(recording, clipped_fraction=scan.clipped, dc_offset=scan.offsets)


def load_recording(path, input_channel: int = 0, output_channel: int = 1) -> Recording:
    """Load a stereo WAV file as a Recording in memory (``open_recording`` then ``load``)."""
    return open_recording(path, input_channel, output_channel).load()


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


def noise_length_rule(transient_s: float = TRANSIENT_S) -> str:
    """What a noise recording needs, in words: the one rule of ``check_noise_length`` (and of
    ``helmet-anc simulate --noise-seconds``)."""
    return (f"more than {transient_s + NOISE_AFTER_TRANSIENT_S:g} s (its first {transient_s:g} s are the excitation's "
            f"start-up and are left out; at least {NOISE_AFTER_TRANSIENT_S:g} s more are needed to estimate the path)")


def check_noise_length(recording: Recording | RecordingFile, transient_s: float = TRANSIENT_S) -> None:
    """RecordingError unless the noise recording lasts more than its transient plus
    ``NOISE_AFTER_TRANSIENT_S``: one rule for identify, diagnose and report (a recording identify
    accepts, the other commands accept too). A WAV file cut short is judged by what it holds."""
    if not recording.duration > transient_s + NOISE_AFTER_TRANSIENT_S:
        raise RecordingError(f"{recording.path}: a noise recording of {recording.duration:.3g} s is too short; it "
                             f"needs {noise_length_rule(transient_s)}")
