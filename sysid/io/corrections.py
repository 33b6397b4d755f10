"""Data corrections a model carries (design.md, "The model"): clock ratio and excluded stretches.

- ``clock_ratio`` r is ear samples per input sample (an ear clock running ppm
  fast has r = 1 + ppm 1e-6). The ear sample taken at input sample k is ear
  sample k r, so the corrected ear signal is y_c[k] = y(k r), read by cubic
  interpolation; the samples the ear channel lacks at the end are dropped from
  both channels.
- ``excluded`` stretches [start_s, stop_s] of a recording (clipped, say) are left
  out: ``excluded_mask`` marks them for validation; for identification ``refine``
  fills them with the previous model's prediction (``sysid.refits``), since stretches
  cut out and joined leave a transient at every joint.

``output_offset`` needs no correction of the data: ``Model.simulate`` adds it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.interpolate

from .recordings import Recording

__all__ = ["resample_ear", "corrected", "excluded_mask", "recording_key"]


def resample_ear(y: np.ndarray, ratio: float) -> np.ndarray:
    """y_c[k] = y(k ratio) for every k whose ear position lies inside the recording."""
    y = np.asarray(y, float)
    if ratio == 1.0:
        return y
    count = int(np.floor((y.size - 1) / ratio)) + 1
    positions = np.arange(min(count, y.size)) * ratio
    return scipy.interpolate.CubicSpline(np.arange(y.size), y)(positions)


def corrected(recording: Recording, clock_ratio: float) -> Recording:
    """The recording with its ear channel resampled by clock_ratio (both channels cut to one length)."""
    if clock_ratio == 1.0:
        return recording
    y = resample_ear(recording.y, clock_ratio)
    n = min(y.size, recording.u.size)
    return Recording(recording.u[:n], y[:n], recording.fs, recording.path, recording.clipped_fraction,
                     recording.dc_offset)


def recording_key(recording: Recording) -> str:
    """The name under which a model's ``excluded`` lists a recording: its file name."""
    return Path(str(recording.path)).name


def excluded_mask(recording: Recording, excluded: dict) -> np.ndarray:
    """True at the samples of the recording that lie in one of its excluded stretches."""
    mask = np.zeros(recording.u.size, bool)
    for start, stop in excluded.get(recording_key(recording), ()):
        mask[int(round(start * recording.fs)):int(round(stop * recording.fs))] = True
    return mask
