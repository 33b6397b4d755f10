"""The ear channel checked: a silent ear channel, or one that does not hear the input, is refused.

A recording whose ear microphone is disconnected, or whose channels are chosen wrongly,
identifies a model of nothing; the loaders of ``sysid.io.recordings`` refuse it with a
one-line RecordingError that names the file, the channels and the fix. Two checks:

* silence: an ear channel whose RMS over the whole recording is below ``SILENT_RMS``
  (half a 16-bit LSB) is digital silence;
* coherence: an ear channel whose median magnitude-squared coherence with the input,
  ``ear_coherence``, is below ``UNCORRELATED_COHERENCE`` does not hear the path. The
  coherence is Welch's (``sysid.io.welch``), over the whole recording and on short
  stretches of it, so that neither a drifting ear clock nor a sweep's briefly excited
  frequencies read as a disconnected ear.

Which of two coherent channels is the input is told elsewhere (``sysid.io.channels``).
"""

from __future__ import annotations

import numpy as np

from ..core.errors import RecordingError
from ..core.thresholds import (EAR_COHERENCE_BAND_HZ, EAR_COHERENCE_SEGMENT, EAR_COHERENCE_STRETCH,
                               EAR_COHERENCE_STRETCHES, SILENT_RMS, UNCORRELATED_COHERENCE)
from .welch import response, streamed_spectra

__all__ = ["check_ear_channel", "ear_coherence"]


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
        raise RecordingError(f"{name}: ear channel {recording.output_channel} does not follow input channel "
                             f"{recording.input_channel} (median coherence {coherence:.2f}); {fix}")


def ear_coherence(recording) -> float | None:
    """Median coherence (Welch, Hann, ``EAR_COHERENCE_SEGMENT``-sample segments) of input and ear
    channel in ``EAR_COHERENCE_BAND_HZ`` (100 Hz - 4 kHz): the larger of its value over the whole
    recording and the median over up to ``EAR_COHERENCE_STRETCHES`` stretches of
    ``EAR_COHERENCE_STRETCH`` samples spread over it (each stretch's own median); None for a
    recording shorter than one stretch."""
    count = min(recording.length // EAR_COHERENCE_STRETCH, EAR_COHERENCE_STRETCHES)
    if count < 1:
        return None
    band = (EAR_COHERENCE_BAND_HZ[0], min(EAR_COHERENCE_BAND_HZ[1], 0.45 * recording.fs))

    def median_coherence(read, length):
        spectra = streamed_spectra(read, length, recording.fs, EAR_COHERENCE_SEGMENT, recording.path)
        coherence = response(spectra, band).coherence
        return float(np.median(coherence)) if coherence.size else np.nan

    whole = median_coherence(recording.read, recording.length)
    stretches = [median_coherence(lambda a, b, start=start: recording.read(start + a, start + b), EAR_COHERENCE_STRETCH)
                 for start in np.linspace(0, recording.length - EAR_COHERENCE_STRETCH, count).astype(int)]
    values = [v for v in (whole, float(np.nanmedian(stretches)) if np.any(np.isfinite(stretches)) else np.nan)
              if np.isfinite(v)]
    return max(values) if values else None
