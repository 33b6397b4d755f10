"""Small signal measurements the figures need: instantaneous frequency, where the error peaks."""

from __future__ import annotations

import numpy as np
import scipy.ndimage
import scipy.signal

__all__ = ["instantaneous_frequency", "min_max_envelope", "moving_rms", "worst_window"]


def instantaneous_frequency(u: np.ndarray, fs: float, smoothing_s: float = 0.005, floor: float = 0.1) -> np.ndarray:
    """Instantaneous frequency (Hz) of a swept sine, NaN where the sweep is silent.

    The derivative of the unwrapped phase of the analytic signal (Hilbert transform),
    median-filtered over ``smoothing_s``; samples whose envelope is below ``floor``
    times the largest envelope (silence, fades) are NaN. Works for linear and
    exponential sweeps alike.
    """
    u = np.asarray(u, dtype=float)
    analytic = scipy.signal.hilbert(u - np.mean(u))
    phase = np.unwrap(np.angle(analytic))
    frequency = np.empty(u.size)
    frequency[1:] = np.diff(phase) * fs / (2 * np.pi)
    frequency[0] = frequency[1] if u.size > 1 else 0.0
    width = max(1, int(smoothing_s * fs)) | 1
    frequency = scipy.ndimage.median_filter(frequency, size=width, mode="nearest")
    envelope = scipy.ndimage.maximum_filter1d(np.abs(analytic), size=width, mode="nearest")
    frequency[envelope < floor * np.max(envelope)] = np.nan
    return frequency


def moving_rms(x: np.ndarray, length: int) -> np.ndarray:
    """RMS of x over a centred window of ``length`` samples (same size as x)."""
    length = max(1, int(length))
    return np.sqrt(scipy.ndimage.uniform_filter1d(np.asarray(x, dtype=float) ** 2, size=length, mode="constant"))


def worst_window(residual: np.ndarray, fs: float, width_s: float = 0.02, skip_s: float = 0.05) -> tuple[int, int]:
    """(start, stop) sample indices of the ``width_s`` window with the largest residual RMS.

    The first ``skip_s`` are ignored, as in the validation rms.
    """
    length = max(2, round(width_s * fs))
    level = moving_rms(residual, length)
    first = min(round(skip_s * fs), max(residual.size - 1, 0))
    centre = first + int(np.argmax(level[first:]))
    start = max(0, centre - length // 2)
    return start, min(residual.size, start + length)


def min_max_envelope(t: np.ndarray, x: np.ndarray, columns: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """(t, x) reduced to the minimum and maximum of each of ``columns`` blocks, interleaved.

    Drawn as a line, this looks like the full signal at figure resolution but has
    4 * columns points instead of hundreds of thousands.
    """
    t, x = np.asarray(t), np.asarray(x)
    if x.size <= 4 * columns:
        return t, x
    step = x.size // columns
    used = step * columns
    blocks = x[:used].reshape(columns, step)
    times = t[:used].reshape(columns, step)
    lowest, highest = blocks.argmin(axis=1), blocks.argmax(axis=1)
    rows = np.arange(columns)
    first = np.minimum(lowest, highest)
    second = np.maximum(lowest, highest)
    t_out = np.stack([times[rows, first], times[rows, second]], axis=1).ravel()
    x_out = np.stack([blocks[rows, first], blocks[rows, second]], axis=1).ravel()
    return t_out, x_out
