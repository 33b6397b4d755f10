"""The input nonlinearity's harmonic levels and drive limit, and the saturation of given harmonic levels.

A static map v = f(u) driven by u = A sin(wt) puts harmonics at 2f, 3f, ...; their levels
relative to the fundamental (dB) are read from the DFT of one period of f(A sin), sampled
finely enough that the aliases of the harmonics kept are negligible
(``harmonic_levels``). A saturation w = s tanh((u + o)/s) - s tanh(o/s) of given third and second
harmonic levels at one amplitude is found by solving for s, then o (``saturation_form``: the third
harmonic rises monotonically as s falls, the second as |o| grows). ``drive_limit`` is the input
amplitude (FS) at which the model's harmonic distortion reaches a given level (-20 dB: 10 %), the
largest drive a controller may command before the driver's nonlinearity dominates the ear signal.

``sweep_harmonics`` measures the harmonics on an exponential sweep (Farina, "Simultaneous measurement
of impulse response and distortion with a swept-sine technique", AES 108th convention, 2000, preprint
5093): the sweep f(t) = f0 e^{t/L} reaches k f a time L ln k after f, so deconvolving the ear signal
by the sweep puts the k-th harmonic's impulse response L ln k before the linear one. Each harmonic
sweep spends the time L dF / F per band dF as the sweep itself does, so the ratio of the k-th
response's spectrum to the linear one's at the same frequency is the harmonic's level at the input
of the path (the plant's response cancels): for a Hammerstein system, the static map's level.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.optimize
import scipy.signal

from ..core.model import Model
from ..io.recordings import Recording

__all__ = ["harmonic_levels", "saturation_form", "tanh_map", "drive_limit", "DRIVE_LIMIT_DB", "SweepHarmonics",
           "sweep_harmonics"]

# Samples per period of the sine read by ``harmonic_levels``: harmonics up to 127 without aliasing.
_PERIOD = 256
# The harmonic distortion (dB re the fundamental) at which ``drive_limit`` places the limit: 10 %.
DRIVE_LIMIT_DB = -20.0
_FLOOR_DB = -200.0


def tanh_map(u: np.ndarray, scale: float, offset: float = 0.0, gain: float = 1.0) -> np.ndarray:
    """w = g (s tanh((u + o)/s) - s tanh(o/s)), the model's saturation form (``sysid.core.model``)."""
    return gain * scale * (np.tanh((np.asarray(u, dtype=float) + offset) / scale) - math.tanh(offset / scale))


def harmonic_levels(static_map: Callable[[np.ndarray], np.ndarray], amplitude: float,
                    orders=(2, 3)) -> dict[int, float]:
    """{k: level of the k-th harmonic in dB re the fundamental} of ``static_map`` at a sine of ``amplitude`` (FS)."""
    phase = 2 * np.pi * np.arange(_PERIOD) / _PERIOD
    spectrum = np.abs(np.fft.rfft(static_map(amplitude * np.sin(phase))))
    fundamental = max(spectrum[1], 1e-300)
    return {k: float(max(20 * np.log10(max(spectrum[k], 1e-300) / fundamental), _FLOOR_DB)) for k in orders}


def saturation_form(h3_db: float, h2_db: float, amplitude: float) -> dict:
    """The saturation {"kind": "tanh", "scale", "gain": 1, "offset"} whose third harmonic at a sine of
    ``amplitude`` (FS) is ``h3_db`` and second ``h2_db`` (dB re the fundamental; -120 or below: none).

    The scale s comes from the symmetric form (H3 of s tanh(u/s) depends on A/s alone), then the
    offset o from H2 at that s. Levels a tanh cannot give (H3 at or above -10 dB, the hard clipper's
    -9.5 dB) raise ValueError.
    """
    if not h3_db < -10.0:
        raise ValueError(f"a tanh saturation gives a third harmonic below -10 dB; asked for {h3_db:g} dB")

    def third(log_ratio):
        return harmonic_levels(lambda u: tanh_map(u, amplitude * math.exp(-log_ratio)), amplitude)[3] - h3_db

    # A/s from 1e-4 (H3 ~ -170 dB) to 30 (nearly a square wave, -9.6 dB).
    log_ratio = scipy.optimize.brentq(third, math.log(1e-4), math.log(30.0), xtol=1e-10)
    scale = amplitude * math.exp(-log_ratio)
    offset = 0.0
    if h2_db > -120.0:
        def second(o):
            return harmonic_levels(lambda u: tanh_map(u, scale, o), amplitude)[2] - h2_db

        top = 3.0 * scale
        if second(top) < 0:
            raise ValueError(f"a tanh of third harmonic {h3_db:g} dB gives a second harmonic below "
                             f"{second(top) + h2_db:.1f} dB only; asked for {h2_db:g} dB")
        offset = scipy.optimize.brentq(second, 0.0, top, xtol=1e-12 * scale)
    return {"kind": "tanh", "scale": float(scale), "gain": 1.0, "offset": float(offset)}


def drive_limit(model: Model, level_db: float = DRIVE_LIMIT_DB, largest: float = 16.0) -> float | None:
    """The input amplitude (FS, peak of a sine) at which the model's input nonlinearity puts its total
    harmonic distortion (harmonics 2-9, power sum re the fundamental) at ``level_db``; None when the model
    has no input nonlinearity or stays below that level up to ``largest`` FS.

    Read on a logarithmic grid of amplitudes (1e-4 to ``largest`` FS, 48 per decade), then refined by
    bisection; the distortion of a polynomial or a tanh rises with the amplitude over that range.
    """
    if model.input_nonlinearity is None and model.input_nonlinearity_form is None:
        return None

    def distortion(amplitude):
        levels = harmonic_levels(model.static_input_nonlinearity, amplitude, range(2, 10))
        return 10 * np.log10(sum(10 ** (v / 10) for v in levels.values()))

    grid = np.geomspace(1e-4, largest, int(48 * np.log10(largest / 1e-4)) + 1)
    above = [k for k, a in enumerate(grid) if distortion(a) >= level_db]
    if not above:
        return None
    k = above[0]
    if k == 0:
        return float(grid[0])
    return float(scipy.optimize.brentq(lambda a: distortion(a) - level_db, grid[k - 1], grid[k], xtol=1e-9))


@dataclass(frozen=True)
class SweepHarmonics:
    """Harmonic levels measured on exponential sweeps: ``levels_db`` {k: dB re the fundamental over the band},
    ``frequencies_hz`` (the sweep's frequency f) and ``curves_db`` {k: level at f, third-octave smoothed},
    the sweep's input ``amplitude`` (FS) and its rate constant ``rate_s`` L (s); ``snr`` {k: the k-th
    response's power over the output noise's in the same window and band} (the noise read on the two
    sweeps' difference; None from one sweep)."""

    levels_db: dict
    frequencies_hz: np.ndarray
    curves_db: dict
    amplitude: float
    rate_s: float
    snr: dict | None = None


# Below this R^2 of ln f(t) against t the sweep is not exponential (Farina's separation needs one).
_EXPONENTIAL_R2 = 0.995
_PRE_S = 0.002          # the window of each response opens this much before its onset
_LONGEST_S = 0.2        # and lasts at most this long


def _exponential_rate(u: np.ndarray, fs: float):
    """(L, f0, f1, amplitude) of an exponential sweep from its analytic signal, or None for another sweep."""
    analytic = scipy.signal.hilbert(u - u.mean())
    envelope = np.abs(analytic)
    active = envelope > 0.5 * np.max(envelope)
    idx = np.flatnonzero(active)
    if idx.size < fs * 0.1:
        return None
    inner = idx[idx.size // 20: idx.size - idx.size // 20]
    frequency = np.diff(np.unwrap(np.angle(analytic)))[inner] * fs / (2 * np.pi)
    if np.any(frequency <= 0):
        return None
    t, logf = inner / fs, np.log(frequency)
    slope, intercept = np.polyfit(t, logf, 1)
    fitted = slope * t + intercept
    r2 = 1.0 - np.sum((logf - fitted) ** 2) / max(np.sum((logf - logf.mean()) ** 2), 1e-300)
    if slope <= 0 or r2 < _EXPONENTIAL_R2:
        return None
    return 1.0 / slope, float(np.exp(fitted[0])), float(np.exp(fitted[-1])), float(np.median(envelope[inner]))


def sweep_harmonics(sweeps: list[Recording], orders=(2, 3), points: int = 24) -> SweepHarmonics | None:
    """The harmonic levels of ``sweeps`` (exponential sweeps of one excitation), or None when they are not
    exponential (see the module docstring). The responses are averaged over the sweeps as power ratios."""
    rate = _exponential_rate(sweeps[0].u, sweeps[0].fs)
    if rate is None:
        return None
    L, f0, f1, amplitude = rate
    fs = sweeps[0].fs
    n = 1 << int(np.ceil(np.log2(2 * sweeps[0].u.size)))
    frequencies = np.fft.rfftfreq(n, 1 / fs)
    inside = (frequencies >= f0) & (frequencies <= f1)
    # The band limited by causal filters (Butterworth, 4th order, at the sweep's ends) and a regularised
    # division: a band cut sharp, or any zero-phase taper, rings before the linear response, into the
    # harmonics' windows (a taper a third of an octave wide at 20 Hz rings for 0.2 s, -49 dB on a linear path).
    edges = [scipy.signal.butter(4, f0, "highpass", fs=fs, output="sos"), scipy.signal.butter(4, f1, fs=fs, output="sos")]
    band_filter = np.prod([scipy.signal.sosfreqz(sos, worN=frequencies, fs=fs)[1] for sos in edges], axis=0)
    powers: dict[int, np.ndarray] = {k: 0.0 for k in (1, *orders)}
    windows = {}
    for k in (1, *orders):
        onset = -L * math.log(k)
        length = min(L * math.log(k / (k - 1)) if k > 1 else L * math.log(2), _LONGEST_S)
        start = int(round((onset - _PRE_S) * fs))
        windows[k] = np.arange(start, start + int(round(length * fs)))

    def responses(u, y):
        U, Y = np.fft.rfft(u - u.mean(), n), np.fft.rfft(y - y.mean(), n)
        power = np.abs(U) ** 2
        h = np.fft.irfft(band_filter * Y * np.conj(U) / (power + 1e-8 * np.max(power)), n)
        return {k: np.abs(np.fft.rfft(np.take(h, window, mode="wrap"), n)) ** 2 for k, window in windows.items()}

    for sweep in sweeps:
        for k, p in responses(sweep.u, sweep.y).items():
            powers[k] = powers[k] + p
    # The output noise in each window: the sweeps repeat one excitation, so their difference is noise
    # alone (of twice one sweep's variance, each sweep adding one variance to the sum above).
    noise = None
    if len(sweeps) >= 2 and sweeps[0].y.size == sweeps[1].y.size:
        noise = {k: p * len(sweeps) / 2 for k, p in responses(sweeps[0].u, sweeps[0].y - sweeps[1].y).items()}
    centres = np.geomspace(f0 * 1.26, f1 / max(orders) / 1.26, points)
    levels, curves, snr = {}, {}, {}
    for k in orders:
        band = inside & (frequencies >= k * f0 * 1.26) & (frequencies <= f1 / 1.26)
        levels[k] = float(10 * np.log10(max(np.sum(powers[k][band]), 1e-300) / max(np.sum(powers[1][band]), 1e-300)))
        if noise is not None:
            snr[k] = float(np.sum(powers[k][band]) / max(np.sum(noise[k][band]), 1e-300))
        curve = []
        for f in centres:
            near = (frequencies >= k * f * 2 ** (-1 / 6)) & (frequencies <= k * f * 2 ** (1 / 6))
            curve.append(10 * np.log10(max(np.sum(powers[k][near]), 1e-300) / max(np.sum(powers[1][near]), 1e-300)))
        curves[k] = np.array(curve)
    return SweepHarmonics(levels, centres, curves, amplitude, L, snr if noise is not None else None)
