"""Is a spectral line a stationary sinusoid (a hum) or a narrowband random process (a ringing mode)?

A hum (mains, an engine order at steady speed) is a sinusoid of constant amplitude and phase over the
whole recording: its spectral width is the record's resolution. A lightly damped mode rung by anything
random (the distortion products of a broadband drive, u^2 through a Q-30 mode, or ambient noise) peaks
like a line too where the input is flat, and the linear input does not explain it
(``sysid.io.lines.driven``), but it is a narrowband random process: its complex envelope wanders at
the mode's bandwidth f/Q (S. O. Rice, "Mathematical analysis of random noise", Bell System Technical
Journal 24, 1945, part III: the envelope and phase of narrowband noise).

``line_departure`` takes the line's complex amplitude a_j in each of ``LINE_SEGMENTS`` equal stretches of
a recording (complex demodulation at the line's frequency under a Hann taper, on one time axis), fits
those phasors with one slowly drifting phasor alpha + beta t_j (the amplitude and frequency drift that
``sysid.io.lines.line_regressor`` allows a line), and measures what departs from it two ways:

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
its own by the search's rule; a real hum at 60 dB above the background is never stationary to 1e-6).

Measured (white background, 5 s at 48 kHz, 30 seeds, every line ``sysid.io.lines.find_lines`` reports):
sinusoids found at 40 to 1.6e7 times their neighbourhood depart by 0.5-1.8 times the background (bound
2.5 at K = 20); noise through a Q-30 mode at 91 Hz, found at 40-100 times, by 59-135 times, Q-100 modes
at 40 and 91 Hz by 134-1322, a Q-300 mode at 500 Hz by 98-360, their departures holding 26-99 % of their
energy. The departure of a mode is independent of how the line search rates it: the Lorentzian skirts
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

__all__ = ["LINE_SEGMENTS", "STATIONARY_P", "BACKGROUND_OFFSETS", "LineDeparture", "segment_phasors", "line_departure",
           "is_stationary"]

# 20 stretches: 0.25 s each of a short session's 5 s (five periods of the lowest line in band, 20 Hz, and a
# Q-30 mode's correlation time at 40 Hz), 36 degrees of freedom for the departures (their chi-square bound
# at STATIONARY_P 2.5 times the background, where 10 stretches would give 3.6).
LINE_SEGMENTS = 20
# A sinusoid is taken for a random process with this probability (the bound's tail).
STATIONARY_P = 1e-6
# The background is measured this many stretch bins (LINE_SEGMENTS / T Hz) either side of the line: beyond
# the Hann main lobe (two bins), 12-32 Hz away on a short session's 5 s, 3.5-9.4 Hz on 17 s.
BACKGROUND_OFFSETS = tuple(range(3, 9))


@dataclass(frozen=True)
class LineDeparture:
    """How far a line's stretches depart from one slowly drifting sinusoid (``line_departure``):
    ``over_background`` the departures' mean power over the background's share (1 for a sinusoid in
    noise), ``share`` their share of the line's energy over the stretches (0 to 1), ``bound`` the
    chi-square bound of ``over_background`` for a sinusoid at ``STATIONARY_P``."""

    over_background: float
    share: float
    bound: float


def segment_phasors(x: np.ndarray, frequency: float, fs: float, segments: int = LINE_SEGMENTS,
                    keep: np.ndarray | None = None, offsets=(0,)) -> tuple[np.ndarray, np.ndarray]:
    """(phasors, gains): the complex amplitudes a_jm (FS, peak: x = |a| cos(2 pi f t + arg a)) at
    ``frequency`` (Hz) plus each of ``offsets`` stretch bins (m fs / L Hz for a stretch of L samples) in
    each of ``segments`` equal stretches of x, shape (segments, offsets), by complex demodulation under a
    Hann taper (its sidelobes keep the other lines and the plant's response out: a rectangular stretch
    lets a line ten bins away through at -30 dB); at offset 0 on one time axis (a stationary sinusoid
    has one phasor in all of them). gains (segments,): each phasor's noise gain sum w^2 / (sum w)^2 (its
    noise power is 4 sigma^2 times that for white noise of variance sigma^2). ``keep`` (boolean, x's
    length): the samples taken (all by default); a stretch with fewer kept samples than four periods of
    the line has no phasors (NaN)."""
    offsets = np.asarray(offsets, int)
    edges = np.linspace(0, x.size, segments + 1).astype(int)
    omega = 2 * np.pi * frequency / fs  # rad per sample
    phasors = np.full((segments, offsets.size), np.nan + 0j)
    gains = np.full(segments, np.nan)
    for j, (start, stop) in enumerate(zip(edges[:-1], edges[1:])):
        taper = np.hanning(stop - start)
        if keep is not None:
            taper = np.where(keep[start:stop], taper, 0.0)
        total = float(np.sum(taper))
        if np.count_nonzero(taper) < 4 * fs / frequency or total <= 0:
            continue
        # Demodulated to the line on the recording's time axis; the DFT of the stretch then holds the line's
        # phasor in bin 0 and its neighbours' in bins m.
        demodulated = taper * x[start:stop] * np.exp(-1j * omega * np.arange(start, stop))
        spectrum = np.fft.fft(demodulated) if np.any(offsets) else np.sum(demodulated, keepdims=True)
        phasors[j] = 2.0 * spectrum[offsets] / total
        gains[j] = float(np.sum(taper**2)) / total**2
    return phasors, gains


def _background(x: np.ndarray, frequency: float, fs: float, keep: np.ndarray | None) -> float:
    """4 sigma^2 (FS^2) of the background around ``frequency`` (Hz): the median over the stretches and
    over ``BACKGROUND_OFFSETS`` either side of |a_jm|^2 / gain_j (``segment_phasors``), over ln 2 (the
    median of an exponential variable is ln 2 times its mean). Measured with the stretches' own taper and
    kept samples, beside the line's main lobe and the band f/Q of a mode it might be."""
    resolution = LINE_SEGMENTS * fs / x.size  # Hz: one stretch's bin
    offsets = [side * m for m in BACKGROUND_OFFSETS for side in (-1, 1)
               if 4 * resolution < frequency + side * m * resolution < fs / 2 - 4 * resolution]
    if not offsets:
        return 0.0
    phasors, gains = segment_phasors(x, frequency, fs, LINE_SEGMENTS, keep, offsets)
    powers = (np.abs(phasors) ** 2 / gains[:, None]).ravel()
    powers = powers[np.isfinite(powers)]
    return float(np.median(powers)) / np.log(2) if powers.size else 0.0


def line_departure(x: np.ndarray, frequency: float, fs: float, keep: np.ndarray | None = None) -> LineDeparture:
    """How far the line of x at ``frequency`` (Hz) departs from one slowly drifting sinusoid over
    ``LINE_SEGMENTS`` stretches (see the module docstring); ``keep`` (boolean, x's length): the samples
    it is measured on (all by default)."""
    phasors, gains = segment_phasors(x, frequency, fs, LINE_SEGMENTS, keep)
    phasors = phasors[:, 0]
    measured = np.isfinite(phasors)
    dof = 2 * (int(measured.sum()) - 2)
    if dof <= 0:
        return LineDeparture(0.0, 0.0, np.inf)
    a = phasors[measured]
    t = (np.flatnonzero(measured) - (LINE_SEGMENTS - 1) / 2) / LINE_SEGMENTS
    noise = np.maximum(_background(x, frequency, fs, keep) * gains[measured], 1e-300)
    # One phasor drifting linearly in time, each stretch weighted by its noise.
    weights = 1.0 / np.sqrt(noise)
    trend = np.column_stack([np.ones(a.size), t])
    theta, *_ = np.linalg.lstsq(trend * weights[:, None], a * weights, rcond=None)
    departure = a - trend @ theta
    energy = float(np.sum(np.abs(a) ** 2))
    return LineDeparture(float(np.sum(np.abs(departure * weights) ** 2) / (dof / 2)),
                         float(np.sum(np.abs(departure) ** 2) / energy) if energy > 0 else 0.0,
                         float(scipy.stats.chi2.ppf(1 - STATIONARY_P, dof) / dof))


def is_stationary(x: np.ndarray, frequency: float, fs: float, keep: np.ndarray | None = None) -> bool:
    """Is the line of x at ``frequency`` (Hz) a stationary sinusoid: its departures from one slowly
    drifting sinusoid within the background's chi-square bound, or below 1 / ``LINE_RATIO`` of its
    energy (``line_departure``)?"""
    found = line_departure(x, frequency, fs, keep)
    return found.over_background <= found.bound or found.share < 1.0 / LINE_RATIO
