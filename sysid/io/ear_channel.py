"""The ear channel checked: a silent ear channel, or one that does not hear the input, is refused.

A recording whose ear microphone is disconnected, or whose channels are chosen wrongly,
identifies a model of nothing; the loaders of ``sysid.io.recordings`` refuse it with a
one-line RecordingError that names the file, the channels and the fix. Two checks:

* silence: an ear channel whose RMS over the whole recording is below ``SILENT_RMS``
  (half a 16-bit LSB) is digital silence;
* coherence: an ear channel of which less than ``UNCORRELATED_COHERENCE`` of the in-band
  power is coherent with the input, ``ear_coherence``, does not hear the path. That share
  is the magnitude-squared coherence weighted by the ear's own power spectrum: the
  coherent output power over the output power (Bendat & Piersol, "Random Data", the
  coherent output spectrum gamma^2 G_yy), so it is judged where the path carries signal.
  A path that rolls off below the sensor noise above 1-2 kHz, as a helmet shell makes
  every feed-forward path, has a low coherence over most of the band's bins (median 0.07
  over 100 Hz-4 kHz for one mode at 52 Hz behind a 1 kHz roll-off) and yet nearly all of
  its ear power coherent (0.9 and more); an ear that hears only noise unrelated to the
  input has about 1/K of it coherent, K the number of averaged segments. The spectra are
  Welch's (``sysid.io.welch``), over the whole recording and on short stretches of it, so
  that neither a drifting ear clock nor a sweep's briefly excited frequencies read as a
  disconnected ear.

Which of two coherent channels is the input is told elsewhere (``sysid.io.channels``).
"""

from __future__ import annotations

import numpy as np

from ..core.errors import RecordingError
from ..core.thresholds import (EAR_COHERENCE_AVERAGES, EAR_COHERENCE_BAND_HZ, EAR_COHERENCE_SEGMENT, EAR_COHERENCE_STRETCH,
                               EAR_COHERENCE_STRETCHES, SILENT_RMS, UNCORRELATED_COHERENCE)
from .welch import Spectra, streamed_spectra

__all__ = ["check_ear_channel", "ear_coherence", "coherent_share", "whole_segment"]


def check_ear_channel(recording, y_energy: float, length: int) -> None:
    """RecordingError for an ear channel that is silent or does not hear the input (disconnected, wrong channel).

    ``recording`` is a ``sysid.io.recordings.RecordingFile`` (or anything with its ``read``,
    ``length``, ``fs``, ``path`` and channel numbers); ``y_energy`` is the sum of the squared ear
    samples (full-scale units) over its ``length`` samples.
    """
    name = recording.path
    fix = "check the microphone, or choose the channels with --input-channel/--output-channel"
    if np.sqrt(y_energy / length) < SILENT_RMS:
        raise RecordingError(f"{name}: ear channel {recording.output_channel} is silent (disconnected microphone?); {fix}")
    coherence = ear_coherence(recording)
    if coherence is not None and coherence < UNCORRELATED_COHERENCE:
        low, high = _band(recording.fs)
        raise RecordingError(f"{name}: ear channel {recording.output_channel} does not follow input channel "
                             f"{recording.input_channel} ({100 * coherence:.0f} % of its power in {low:g}-{high:g} Hz "
                             f"is coherent with the input); {fix}")


def _band(fs: float) -> tuple[float, float]:
    """``EAR_COHERENCE_BAND_HZ`` (Hz), its top below Nyquist."""
    return EAR_COHERENCE_BAND_HZ[0], min(EAR_COHERENCE_BAND_HZ[1], 0.45 * fs)


def coherent_share(spectra: Spectra, band: tuple[float, float]) -> float:
    """The share of the ear's power in ``band`` (Hz) that is coherent with the input, in [0, 1]:
    sum gamma^2 S_yy / sum S_yy = sum |S_yu|^2 / S_uu / sum S_yy over the band's bins; NaN for
    a band without ear power. Bins where the input has no power hold no coherent power."""
    f = spectra.frequencies
    inside = (f >= band[0]) & (f <= band[1])
    s_uu, s_yu, s_yy = spectra.s_uu[inside], spectra.s_yu[inside], spectra.s_yy[inside]
    total = float(np.sum(s_yy))
    if not total > 0:
        return np.nan
    coherent = np.abs(s_yu[s_uu > 0]) ** 2 / s_uu[s_uu > 0]
    return float(min(np.sum(coherent) / total, 1.0))


def whole_segment(length: int) -> int:
    """Welch segment (samples) of the whole-recording share: the longest power of two, from
    ``EAR_COHERENCE_SEGMENT`` up, that still gives ``EAR_COHERENCE_AVERAGES`` half-overlapping
    segments in ``length`` samples.

    A segment shorter than the path's memory biases the coherence low where the path rings
    (Bendat & Piersol, "Random Data", the resolution bias of spectral estimates): a path with a
    mode at 101 Hz of Q 26 (time constant 82 ms) shared 0.10 of its ear power coherently in
    segments of 512 samples and 0.75 in 8192 (8 s of noise, sensor noise 3e-4 FS). An ear unrelated to the input shares about 1 / averages
    at any length, so the longest segment that keeps the averages is taken.
    """
    segment = EAR_COHERENCE_SEGMENT
    while length >= (EAR_COHERENCE_AVERAGES + 1) * segment:
        segment *= 2
    return segment


def ear_coherence(recording) -> float | None:
    """The share of the ear channel's power in ``EAR_COHERENCE_BAND_HZ`` (20 Hz - 4 kHz) that is
    coherent with the input (``coherent_share``; Welch, Hann): the larger of its value over the
    whole recording (segments of ``whole_segment``) and the median over up to
    ``EAR_COHERENCE_STRETCHES`` stretches of ``EAR_COHERENCE_STRETCH`` samples spread over it
    (each stretch's own share, segments of ``EAR_COHERENCE_SEGMENT``); None for a recording
    shorter than one stretch."""
    count = min(recording.length // EAR_COHERENCE_STRETCH, EAR_COHERENCE_STRETCHES)
    if count < 1:
        return None
    band = _band(recording.fs)
    segment = whole_segment(recording.length)
    # The same memory per block of segments whatever their length.
    segments_per_block = max(1, 256 * EAR_COHERENCE_SEGMENT // segment)

    def share(read, length):
        return coherent_share(streamed_spectra(read, length, recording.fs, EAR_COHERENCE_SEGMENT, recording.path), band)

    whole = coherent_share(streamed_spectra(recording.read, recording.length, recording.fs, segment,
                                            recording.path, segments_per_block), band)
    stretches = [share(lambda a, b, start=start: recording.read(start + a, start + b), EAR_COHERENCE_STRETCH)
                 for start in np.linspace(0, recording.length - EAR_COHERENCE_STRETCH, count).astype(int)]
    values = [v for v in (whole, float(np.nanmedian(stretches)) if np.any(np.isfinite(stretches)) else np.nan)
              if np.isfinite(v)]
    return max(values) if values else None
