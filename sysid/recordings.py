"""Stereo WAV recordings of one sound path, loaded and checked against the input contract.

Channel 0 is the path input (headphone drive voltage for FB, chin microphone for FF)
and channel 1 the ear-canal microphone, unless overridden. Samples are scaled to
full-scale units in [-1, 1): 16-bit PCM by 2^-15, 24/32-bit PCM (which scipy returns
left-justified in int32) by 2^-31, 8-bit unsigned PCM by (x - 128)/128, float as is.
Anything unusable raises RecordingError with a one-line message naming the file;
clipping and a DC offset are reported (a RecordingWarning and the fields
``clipped_fraction`` and ``dc_offset``) because the diagnosis explains them.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.io.wavfile

from .data_quality import clipped_samples, dc_offset
from .errors import RecordingError

__all__ = ["Recording", "RecordingWarning", "load_recording", "check_same_rate", "write_wav16", "recording_from_arrays"]


class RecordingWarning(UserWarning):
    """A recording is usable but has a data-quality problem (clipping, DC offset)."""


@dataclass
class Recording:
    """One stereo recording: input u and ear signal y in full-scale units at fs Hz."""

    u: np.ndarray
    y: np.ndarray
    fs: float
    path: str = "<array>"
    clipped_fraction: tuple[float, float] = (0.0, 0.0)
    dc_offset: tuple[float, float] = (0.0, 0.0)

    @property
    def duration(self) -> float:
        return self.u.size / self.fs

    def trimmed(self, start_s: float) -> "Recording":
        """The recording without its first start_s seconds (e.g. the 3 s noise transient)."""
        first = int(round(start_s * self.fs))
        return Recording(self.u[first:], self.y[first:], self.fs, self.path, self.clipped_fraction, self.dc_offset)


def _to_full_scale(data: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Float samples in [-1, 1) and the rail values (lowest, highest) of the format."""
    if data.dtype == np.int16:
        return data / 32768.0, -1.0, 32767 / 32768.0
    if data.dtype == np.int32:
        return data / 2147483648.0, -1.0, 2147483392 / 2147483648.0
    if data.dtype == np.uint8:
        return (data.astype(float) - 128.0) / 128.0, -1.0, 127 / 128.0
    if data.dtype.kind == "f":
        return data.astype(float), -1.0, 1.0
    raise RecordingError(f"unsupported sample format {data.dtype}")


def _check_samples(name: str, u: np.ndarray, y: np.ndarray) -> None:
    for label, x in (("input", u), ("output", y)):
        if not np.all(np.isfinite(x)):
            raise RecordingError(f"{name}: {label} channel has NaN or infinite samples")
    if u.size == 0:
        raise RecordingError(f"{name}: recording has no samples")
    if not np.any(u):
        raise RecordingError(f"{name}: input channel is silent (all samples zero)")


def _quality(name: str, u: np.ndarray, y: np.ndarray, rails: tuple[float, float]) -> tuple[tuple, tuple]:
    clipped = []
    offsets = []
    for label, x in (("input", u), ("output", y)):
        # One clipping and one DC algorithm for loader, diagnosis and refine (sysid.data_quality).
        fraction = clipped_samples(x, rails).fraction
        clipped.append(fraction)
        if fraction:
            warnings.warn(f"{name}: {label} channel clipped on {100 * fraction:.3g} % of samples", RecordingWarning, stacklevel=3)
        offset, significant = dc_offset(x)
        offsets.append(offset if significant else 0.0)
        if significant:
            warnings.warn(f"{name}: {label} channel has a DC offset of {offset:.3g} FS", RecordingWarning, stacklevel=3)
    return tuple(clipped), tuple(offsets)


def load_recording(path, input_channel: int = 0, output_channel: int = 1) -> Recording:
    """Load a stereo WAV file as a Recording (see the module docstring for scaling)."""
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
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", scipy.io.wavfile.WavFileWarning)
            fs, data = scipy.io.wavfile.read(path)
    except Exception as exc:  # scipy raises several types (and some internal ones) on corrupt files
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise RecordingError(f"{name}: not a readable WAV file ({reason})") from None
    if data.ndim == 1:
        raise RecordingError(f"{name}: mono file; expected 2 channels (input, ear microphone)")
    channels = data.shape[1]
    for label, index in (("input", input_channel), ("output", output_channel)):
        if not 0 <= index < channels:
            raise RecordingError(f"{name}: {label} channel {index} does not exist (file has {channels} channels)")
    if input_channel == output_channel:
        raise RecordingError(f"{name}: input and output channel are both {input_channel}")
    try:
        scaled, low, high = _to_full_scale(data)
    except RecordingError as exc:
        raise RecordingError(f"{name}: {exc}") from None
    u = np.ascontiguousarray(scaled[:, input_channel], dtype=float)
    y = np.ascontiguousarray(scaled[:, output_channel], dtype=float)
    _check_samples(name, u, y)
    _check_ear_channel(name, u, y, float(fs), input_channel, output_channel)
    clipped, offsets = _quality(name, u, y, (low, high))
    return Recording(u, y, float(fs), name, clipped, offsets)


# Loading holds the samples as float64 (4x a 16-bit file): 2 GiB of WAV is 8 GiB of memory.
MAX_RECORDING_BYTES = 2 * 2**30
# An ear channel below half a 16-bit LSB (RMS) is digital silence: nothing is connected.
SILENT_RMS = 2.0**-16
# Median magnitude-squared coherence between input and ear channel, 100 Hz - 4 kHz, below which
# the ear microphone does not hear the path at all. Sessions of the appendix-A plants and of
# random helmet paths (sysid.random_plant, seeds 0-5, both paths) measure 0.89 to 0.999.
UNCORRELATED_COHERENCE = 0.1
_COHERENCE_SEGMENT = 1024


def _check_ear_channel(name: str, u: np.ndarray, y: np.ndarray, fs: float, input_channel: int,
                       output_channel: int) -> None:
    """RecordingError for an ear channel that is silent or does not hear the input (disconnected, wrong channel)."""
    fix = "check the microphone, or choose the channels with --input-channel/--output-channel"
    if np.sqrt(np.mean(y**2)) < SILENT_RMS:
        raise RecordingError(f"{name}: ear channel {output_channel} is silent (disconnected microphone?); {fix}")
    if u.size < 8 * _COHERENCE_SEGMENT:
        return
    import scipy.signal

    f, coherence = scipy.signal.coherence(u, y, fs, nperseg=_COHERENCE_SEGMENT)
    band = (f >= 100.0) & (f <= min(4000.0, 0.45 * fs))
    if band.any() and float(np.median(coherence[band])) < UNCORRELATED_COHERENCE:
        raise RecordingError(f"{name}: ear channel {output_channel} does not follow input channel {input_channel} "
                             f"(median coherence {float(np.median(coherence[band])):.2f}); {fix}")


def recording_from_arrays(u, y, fs: float, name: str = "<array>") -> Recording:
    """A Recording from numpy arrays (full-scale units), with the same checks as a file."""
    u = np.asarray(u, dtype=float).reshape(-1)
    y = np.asarray(y, dtype=float).reshape(-1)
    if u.size != y.size:
        raise RecordingError(f"{name}: input has {u.size} samples but output has {y.size}")
    if not (np.isfinite(fs) and fs > 0):
        raise RecordingError(f"{name}: sample rate must be positive; found {fs}")
    _check_samples(name, u, y)
    clipped, offsets = _quality(name, u, y, (-1.0, 32767 / 32768.0))
    return Recording(u, y, float(fs), name, clipped, offsets)


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


def write_wav16(path, u: np.ndarray, y: np.ndarray, fs: float) -> None:
    """Write a stereo 16-bit PCM WAV (channel 0 = u, channel 1 = y), rounding and saturating."""
    stereo = np.stack([u, y], axis=1) * 32768.0
    pcm = np.clip(np.round(stereo), -32768, 32767).astype(np.int16)
    scipy.io.wavfile.write(path, int(round(fs)), pcm)
