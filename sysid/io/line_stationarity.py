"""Is a spectral line a stationary sinusoid (a hum) or a narrowband random process (a ringing mode)?

A hum (mains, an engine order at steady speed) is a sinusoid of constant amplitude and phase over the
whole recording: its spectral width is the record's resolution. A lightly damped mode rung by anything
random (the distortion products of a broadband drive, u^2 through a Q-30 mode, or ambient noise) peaks
like a line too where the input is flat, and the linear input does not explain it
(``sysid.io.lines.driven``), but it is a narrowband random process: its complex envelope wanders at
the mode's bandwidth f/Q (S. O. Rice, "Mathematical analysis of random noise", Bell System Technical
Journal 24, 1945, part III: the envelope and phase of narrowband noise).

``line_departure`` takes the line's complex amplitude a_j in each stretch of ``LINE_STRETCH_S`` of a
recording (complex demodulation at the line's frequency under a Hann taper, on one time axis), fits the
phasors of each block of ``LINE_SEGMENTS`` stretches with one slowly drifting phasor alpha + beta t_j (the
amplitude and frequency drift that ``sysid.io.lines.line_regressor`` allows a line), and measures what
departs from it two ways (the median over the blocks):

- against the background: sum_j |a_j - alpha - beta t_j|^2 / nu_j / (K - 2), nu_j the noise power of
  stretch j's phasor, measured beside the line: the median of |a|^2 at ``BACKGROUND_OFFSETS`` stretch
  bins either side (beyond the taper's main lobe and a resolvable mode's band), over ln 2 for the mean
  of an exponential variable. For a sinusoid in noise this is a chi-square variable with 2 (K - 2)
  degrees of freedom over its mean, about 1; a random process puts its own power, far above the
  background where it stands out as a line, into every stretch's departure;
- against the line: the departures' share of the phasors' energy, which a narrowband process whose band
  the record resolves keeps large, and which for a sinusoid is what its slow modulation and the noise
  leave.

``is_stationary``: the departures are within the background's chi-square bound at ``STATIONARY_P`` (a weak
line: its stretches' phasors are as noisy as the background makes them), or they hold less than
1 / ``LINE_RATIO`` of the line's energy (a strong line: a modulation too weak to stand out as a line of
its own by the search's rule; a real hum 60 dB above the background is not constant to a part in a million).

Measured (white background, 48 kHz, every line ``sysid.io.lines.find_lines`` reports; 5 s, 30 seeds):
sinusoids found at 40 to 1.6e7 times their neighbourhood depart by 0.5-1.8 times the background (bound
2.5); noise through a Q-30 mode at 91 Hz, found at 40-100 times, by 59-135 times, Q-100 modes at 40 and
91 Hz by 134-1322, a Q-300 mode at 500 Hz by 98-360, their departures holding 26-99 % of their energy.
On 17 s (three blocks, 6 seeds): sinusoids 0.7-1.2, modes 70-1339.
The departure of a mode is independent of how the line search rates it: the Lorentzian skirts
of a mode set the median of the search's 20 Hz neighbourhood, the stretches' offsets are beyond them.
The stretches' phasors of a mode are independent when each outlasts its correlation time Q / (pi f); a
mode narrower than the record's resolution (f/Q below about 1 / T) is not told from a line by any test
on that record.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.stats

from ..core.thresholds import LINE_RATIO

__all__ = ["LINE_STRETCH_S", "LINE_SEGMENTS", "STATIONARY_P", "BACKGROUND_OFFSETS", "LineDeparture", "segment_phasors",
           "line_departure", "line_significance", "is_stationary"]

# A stretch: 0.25 s, five periods of the lowest line in band (20 Hz) and a Q-30 mode's correlation time at
# 40 Hz; its bins are 4 Hz apart, whatever the recording's length.
LINE_STRETCH_S = 0.25
# Stretches judged together: 20 (5 s, a short session's noise recording after its transient) give the
# departures 36 degrees of freedom, their chi-square bound at STATIONARY_P 2.5 times the background (10 would
# give 3.6). A longer recording is judged in blocks of 20 stretches, and by its median block.
LINE_SEGMENTS = 20
# A sinusoid is taken for a random process with this probability (the bound's tail).
STATIONARY_P = 1e-6
# The background is measured this many stretch bins either side of the line, 12-32 Hz: beyond the Hann
# main lobe (two bins) and the band f/Q of a mode that stands out as a line against a 20 Hz neighbourhood.
BACKGROUND_OFFSETS = tuple(range(3, 9))


@dataclass(frozen=True)
class LineDeparture:
    """How far a line's stretches depart from one slowly drifting sinusoid (``line_departure``), the
    median over blocks of ``LINE_SEGMENTS`` stretches: ``over_background`` the departures' mean power over
    the background's (about 1 for a sinusoid in noise), ``share`` their share of the line's energy over
    the stretches (0 to 1), ``bound`` the chi-square bound of ``over_background`` for a sinusoid at
    ``STATIONARY_P``."""

    over_background: float
    share: float
    bound: float


def segment_phasors(x: np.ndarray, frequency: float, fs: float, keep: np.ndarray | None = None,
                    offsets=(0,)) -> tuple[np.ndarray, np.ndarray]:
    """(phasors, gains): the complex amplitudes a_jm (FS, peak: x = |a| cos(2 pi f t + arg a)) at
    ``frequency`` (Hz) plus each of ``offsets`` stretch bins (1 / ``LINE_STRETCH_S`` Hz each) in each
    stretch j of ``LINE_STRETCH_S`` of x (the remainder at the end left out), shape (stretches, offsets),
    by complex demodulation under a Hann taper (its sidelobes keep the other lines and the plant's
    response out: a rectangular stretch lets a line ten bins away through at -30 dB); at offset 0 on one
    time axis (a stationary sinusoid has one phasor in all of them). gains (stretches,): each phasor's
    noise gain sum w^2 / (sum w)^2 (its noise power is 4 sigma^2 times that for white noise of variance
    sigma^2). ``keep`` (boolean, x's length): the samples taken (all by default); a stretch with fewer
    kept samples than four periods of the line has no phasors (NaN)."""
    offsets = np.asarray(offsets, int)
    length = int(round(LINE_STRETCH_S * fs))
    stretches = x.size // length
    omega = 2 * np.pi * frequency / fs  # rad per sample
    phasors = np.full((stretches, offsets.size), np.nan + 0j)
    gains = np.full(stretches, np.nan)
    hann = np.hanning(length)
    for j in range(stretches):
        start, stop = j * length, (j + 1) * length
        taper = hann if keep is None else np.where(keep[start:stop], hann, 0.0)
        total = float(np.sum(taper))
        if np.count_nonzero(taper) < 4 * fs / frequency or total <= 0:
            continue
        # Demodulated to the line on the recording's time axis, the stretch's DFT holds the line's phasor in
        # bin 0 and its neighbours' in bins m.
        demodulated = taper * x[start:stop] * np.exp(-1j * omega * np.arange(start, stop))
        spectrum = np.fft.fft(demodulated) if np.any(offsets) else np.sum(demodulated, keepdims=True)
        phasors[j] = 2.0 * spectrum[offsets] / total
        gains[j] = float(np.sum(taper**2)) / total**2
    return phasors, gains


def _beside(frequency: float, fs: float) -> list[int]:
    """The stretch bins (signed offsets, ``BACKGROUND_OFFSETS`` either side) the background beside a line at
    ``frequency`` (Hz) is measured at: those at least four bins inside 0 and fs / 2."""
    resolution = 1.0 / LINE_STRETCH_S  # Hz: one stretch's bin
    return [side * m for m in BACKGROUND_OFFSETS for side in (-1, 1)
            if 4 * resolution < frequency + side * m * resolution < fs / 2 - 4 * resolution]


def _block_departure(a: np.ndarray, gains: np.ndarray, around: np.ndarray) -> tuple[float, float, int]:
    """(departure over the background, departure share, degrees of freedom) of one block's phasors a
    (NaN where a stretch has none), their noise gains, and the phasors beside the line ``around``
    (stretches, offsets): the background's 4 sigma^2 is the median of |around|^2 / gain over ln 2 (the
    median of an exponential variable is ln 2 times its mean)."""
    measured = np.isfinite(a)
    dof = 2 * (int(measured.sum()) - 2)
    powers = (np.abs(around[measured]) ** 2 / gains[measured, None]).ravel()
    if dof <= 0 or powers.size == 0:
        return 0.0, 0.0, 0
    background = float(np.median(powers)) / np.log(2)
    t = (np.flatnonzero(measured) - (a.size - 1) / 2) / a.size
    weights = 1.0 / np.sqrt(np.maximum(background * gains[measured], 1e-300))
    # One phasor drifting linearly in time, each stretch weighted by its noise.
    trend = np.column_stack([np.ones(t.size), t])
    theta, *_ = np.linalg.lstsq(trend * weights[:, None], a[measured] * weights, rcond=None)
    departure = a[measured] - trend @ theta
    energy = float(np.sum(np.abs(a[measured]) ** 2))
    return (float(np.sum(np.abs(departure * weights) ** 2) / (dof / 2)),
            float(np.sum(np.abs(departure) ** 2) / energy) if energy > 0 else 0.0, dof)


def line_departure(x: np.ndarray, frequency: float, fs: float, keep: np.ndarray | None = None) -> LineDeparture:
    """How far the line of x at ``frequency`` (Hz) departs from one slowly drifting sinusoid (see the
    module docstring), the median over blocks of ``LINE_SEGMENTS`` stretches (one block of what there is
    on a recording shorter than that); ``keep`` (boolean, x's length): the samples it is measured on (all
    by default). No departure, and an infinite bound, when fewer than three stretches hold the line."""
    beside = _beside(frequency, fs)
    phasors, gains = segment_phasors(x, frequency, fs, keep, [0, *beside])
    blocks = [slice(b * LINE_SEGMENTS, (b + 1) * LINE_SEGMENTS) for b in range(max(phasors.shape[0] // LINE_SEGMENTS, 1))]
    found = [_block_departure(phasors[block, 0], gains[block], phasors[block, 1:]) for block in blocks]
    found = [f for f in found if f[2] > 0]
    if not found:
        return LineDeparture(0.0, 0.0, np.inf)
    dof = min(f[2] for f in found)
    return LineDeparture(float(np.median([f[0] for f in found])), float(np.median([f[1] for f in found])),
                         float(scipy.stats.chi2.ppf(1 - STATIONARY_P, dof) / dof))


def line_significance(x: np.ndarray, frequency: float, fs: float) -> float:
    """z^2 of the sinusoid at ``frequency`` (Hz) in x: |a|^2 / var(a) of its phasor a averaged over the
    stretches of ``LINE_STRETCH_S``, each weighted by its own background (the median of |a_jm|^2 at
    ``BACKGROUND_OFFSETS`` beside the line in that stretch, over ln 2). Where the background changes
    along x (a sweep's residual: the model's misfit and the drive's harmonics pass each frequency in
    turn), the stretches the sweep's error crosses count for little; 0 when no stretch holds the line."""
    beside = _beside(frequency, fs)
    phasors, _ = segment_phasors(x, frequency, fs, None, [0, *beside])
    if not beside or phasors.shape[0] == 0:
        return 0.0
    noise = np.median(np.abs(phasors[:, 1:]) ** 2, axis=1) / np.log(2)
    measured = np.isfinite(phasors[:, 0]) & (noise > 0)
    if not np.any(measured):
        return 0.0
    weights = 1.0 / noise[measured]
    mean = np.sum(weights * phasors[measured, 0]) / np.sum(weights)
    return float(np.abs(mean) ** 2 * np.sum(weights))


def is_stationary(x: np.ndarray, frequency: float, fs: float, keep: np.ndarray | None = None) -> bool:
    """Is the line of x at ``frequency`` (Hz) a stationary sinusoid: its departures from one slowly
    drifting sinusoid within the background's chi-square bound, or below 1 / ``LINE_RATIO`` of its
    energy (``line_departure``)?"""
    found = line_departure(x, frequency, fs, keep)
    return found.over_background <= found.bound or found.share < 1.0 / LINE_RATIO
