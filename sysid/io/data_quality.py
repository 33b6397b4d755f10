"""Data quality of one recorded channel: DC offset and clipping, one algorithm each.

Used by the loader's warnings (``sysid.io.recordings``), by the diagnosis findings
(``sysid.findings.data_quality``) and by the data corrections of ``refine``.

- DC offset: the median of the means of 16 equal parts. A real offset shifts
  every part alike, while the slow response of a plant with a pole near z = 1
  moves the mean of a few parts only. Significant when it exceeds twice the robust
  spread of the part means (1.4826 MAD), ``DC_RELATIVE`` of the channel RMS and
  ``DC_ABSOLUTE``.
- Clipping at any level (a converter at its rails or a preamplifier that
  flat-tops well below them): for each polarity the samples within ``TOP_WIDTH``
  (relative) of the channel's extreme value, or ``NOISE_WIDTHS`` times its noise
  RMS when that is wider (noise after the clipper scatters the tops), form the top bin, the same width just
  below it the next bin. A clipped channel piles its flat tops into the top bin, a
  spike in the histogram many times the next bin; an unclipped sine (arcsine
  density) gives a ratio of sqrt(2) + 1 = 2.4, noise much less. Samples at the
  converter's rails count as clipped whatever the histogram.
- Clipping against a prediction (``clipped_against_prediction``): sensor noise added
  after the clipper scatters a flat top over several noise widths, and the histogram
  spike falls below ``SPIKE_RATIO`` (a preamplifier at 0.12 FS with noise of 0.7 % of
  its clip level: 2.3x). A model's prediction tells what the signal should have been:
  where the prediction goes beyond the measured extreme by more than half the noise
  band (and by more than its scatter elsewhere), a clipped channel stays flat, within
  noise of its clip level, while the prediction moves (the measured signal against the
  predicted one has a slope near 0 there); a channel that only differs from the model
  (a missing nonlinearity, gain or delay, an offset) follows the prediction with a slope
  near 1, and a good model never goes that far beyond the measured extreme.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["dc_offset", "clipped_samples", "clipped_against_prediction", "clipped_stretches", "Clipping",
           "DC_RELATIVE", "DC_ABSOLUTE", "CLIP_MIN_SAMPLES", "RAILS_16BIT"]

DC_RELATIVE = 0.02
DC_ABSOLUTE = 1e-4
# Fewer clipped samples than this are legitimate peaks.
CLIP_MIN_SAMPLES = 3
RAILS_16BIT = (-1.0, 32767 / 32768.0)
# Top-bin width relative to the extreme value (0.5 %, 0.04 dB), and how many times the next bin
# the top bin must hold to be a clipping spike rather than the peak of a sine.
TOP_WIDTH = 0.005
SPIKE_RATIO = 6.0
# A spike needs this many samples in the top bin: with the next bin empty or nearly, a few samples are
# the extremes of a few cycles of a sweep through a resonance (a clean random helmet: 7 in the top bin,
# 1 in the next, one sample per cycle), not a flat top.
SPIKE_MIN_SAMPLES = 10
# The top bin is at least NOISE_WIDTHS times the channel's noise RMS wide, at most MAX_WIDTH of the level.
NOISE_WIDTHS = 8.0
MAX_WIDTH = 0.2
# Clipping against a prediction: at least FLAT_MIN_SAMPLES samples predicted beyond the measured extreme,
# where the measured signal rises by at most FLAT_SLOPE per unit of prediction.
FLAT_MIN_SAMPLES = 10
FLAT_SLOPE = 0.25
# ... and predicted beyond it by at least RESIDUAL_WIDTHS times the prediction's robust RMS misfit.
RESIDUAL_WIDTHS = 5.0


def _noise_rms(x: np.ndarray) -> float:
    """Robust RMS of the broadband noise on x: the third difference removes any slow signal
    (a 1 kHz tone is down 39 dB) and white noise comes out sqrt(20) times larger; MAD to RMS."""
    if x.size < 8:
        return 0.0
    return float(np.median(np.abs(np.diff(x, 3))) / 0.6745 / np.sqrt(20.0))


def dc_offset(x: np.ndarray, segments: int = 16) -> tuple[float, bool]:
    """(offset in FS, whether it is significant); see the module docstring."""
    x = np.asarray(x, float)
    parts = np.array([part.mean() for part in np.array_split(x, min(segments, x.size))])
    offset = float(np.median(parts))
    spread = 1.4826 * float(np.median(np.abs(parts - offset)))
    rms = float(np.sqrt(np.mean((x - offset) ** 2)))
    significant = abs(offset) > DC_ABSOLUTE and abs(offset) > DC_RELATIVE * rms and abs(offset) > 2 * spread
    return offset, significant


@dataclass(frozen=True)
class Clipping:
    """Clipped samples of one channel: boolean mask, the clip levels found (FS), the fraction."""

    mask: np.ndarray
    levels: tuple[float, ...]

    @property
    def fraction(self) -> float:
        return float(np.count_nonzero(self.mask) / self.mask.size) if self.mask.size else 0.0


def clipped_samples(x: np.ndarray, rails: tuple[float, float] = RAILS_16BIT, predicted: np.ndarray | None = None
                    ) -> Clipping:
    """The samples of x that sit at a clip level (any level, either polarity); see the module docstring.

    With ``predicted`` (a model's prediction of x), also the flat tops the noise after the clipper
    hides from the histogram (``clipped_against_prediction``), at a polarity the histogram misses.
    """
    x = np.asarray(x, float)
    mask = (x <= rails[0]) | (x >= rails[1])
    levels = []
    if np.count_nonzero(mask) >= CLIP_MIN_SAMPLES:
        levels += [float(x[mask].min())] if np.any(x <= rails[0]) else []
        levels += [float(x[mask].max())] if np.any(x >= rails[1]) else []
    else:
        mask[:] = False
    noise = _noise_rms(x)
    for sign in (1.0, -1.0):
        s = sign * x
        top = float(s.max()) if s.size else 0.0
        if top <= 0.0:
            continue
        # Noise added after the clipper scatters the flat tops: the top bin must hold that scatter.
        width = min(max(TOP_WIDTH * top, NOISE_WIDTHS * noise), MAX_WIDTH * top)
        in_top = s >= top - width
        n_top = int(np.count_nonzero(in_top))
        n_next = int(np.count_nonzero((s >= top - 2 * width) & ~in_top))
        if n_top >= SPIKE_MIN_SAMPLES and n_top > SPIKE_RATIO * max(n_next, 1):
            mask |= in_top
            levels.append(sign * top)
    if predicted is not None:
        against = clipped_against_prediction(x, predicted)
        for level in against.levels:
            if not any(np.sign(v) == np.sign(level) for v in levels):
                mask[: against.mask.size] |= against.mask & (np.sign(level) * x[: against.mask.size] > 0)
                levels.append(level)
    return Clipping(mask, tuple(sorted(set(levels))))


def clipped_against_prediction(x: np.ndarray, predicted: np.ndarray) -> Clipping:
    """The samples of x (measured, FS) that sit flat at a clip level where ``predicted`` (a model's
    prediction of x, FS) goes beyond it; see the module docstring.

    Per polarity: the band W is the histogram test's top bin (``NOISE_WIDTHS`` noise RMS, at least
    ``TOP_WIDTH`` of the extreme); the samples predicted beyond the measured extreme by more than
    W/2 and ``RESIDUAL_WIDTHS`` times the robust RMS of predicted minus measured (away from the
    extremes: noise on the input passes through the model into the prediction, which then strays
    beyond the measured extreme by chance, its excess uncorrelated with the measurement) are the
    candidates. Clipping when there are at least ``FLAT_MIN_SAMPLES``, the prediction
    spreads over them by at least W/4 while the measured signal spreads by at most W/2, and the
    least-squares slope of measured on predicted there is at most ``FLAT_SLOPE``. The clip level is
    the measured median over the candidates; every sample within W/2 of it (or beyond) is clipped.
    """
    x, predicted = np.asarray(x, float), np.asarray(predicted, float)
    n = min(x.size, predicted.size)
    x, predicted = x[:n], predicted[:n]
    mask = np.zeros(x.size, bool)
    levels = []
    noise = _noise_rms(x)
    # The prediction's own scatter about the measurement where neither is near a clip level (robust
    # RMS): input noise passes through the model into the prediction, not into the measurement.
    quiet = np.abs(predicted) < 0.5 * np.max(np.abs(x), initial=0.0)
    residual = (predicted - x)[quiet] if np.count_nonzero(quiet) >= 100 else predicted - x
    misfit = 1.4826 * float(np.median(np.abs(residual - np.median(residual)))) if residual.size else 0.0
    for sign in (1.0, -1.0):
        s, p = sign * x, sign * predicted
        top = float(s.max()) if s.size else 0.0
        if top <= 0.0:
            continue
        width = min(max(TOP_WIDTH * top, NOISE_WIDTHS * noise), MAX_WIDTH * top)
        beyond = p > top + max(width / 2, RESIDUAL_WIDTHS * misfit)
        if np.count_nonzero(beyond) < FLAT_MIN_SAMPLES:
            continue
        measured, moved = s[beyond], p[beyond]
        spread = float(np.std(moved))
        if spread < width / 4 or float(np.std(measured)) > width / 2:
            continue
        slope = float(np.mean((measured - measured.mean()) * (moved - moved.mean()))) / spread**2
        if slope > FLAT_SLOPE:
            continue
        level = float(np.median(measured))
        mask |= s >= level - width / 2
        levels.append(sign * level)
    return Clipping(mask, tuple(sorted(levels)))


def clipped_stretches(mask: np.ndarray, fs: float, margin_s: float) -> list[list[float]]:
    """[start_s, stop_s] of the clipped runs of mask, each widened by margin_s and merged when they touch."""
    index = np.flatnonzero(mask)
    if index.size == 0:
        return []
    margin = int(round(margin_s * fs))
    breaks = np.flatnonzero(np.diff(index) > 2 * margin + 1)
    starts = np.concatenate(([index[0]], index[breaks + 1])) - margin
    stops = np.concatenate((index[breaks], [index[-1]])) + margin + 1
    return [[max(float(a), 0.0) / fs, min(float(b), mask.size) / fs] for a, b in zip(starts, stops)]
