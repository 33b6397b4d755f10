"""The input nonlinearity's harmonic levels and drive limit, and the saturation of given harmonic levels.

A static map v = f(u) driven by u = A sin(wt) puts harmonics at 2f, 3f, ...; their levels
relative to the fundamental (dB) are read from the DFT of one period of f(A sin), sampled
finely enough that the aliases of the harmonics kept are negligible
(``harmonic_levels``). A saturation w = s tanh((u + o)/s) - s tanh(o/s) of given third and second
harmonic levels at one amplitude is found by solving for s, then o (``saturation_form``: the third
harmonic rises monotonically as s falls, the second as |o| grows). ``drive_limit`` is the input
amplitude (FS) at which the model's harmonic distortion reaches a given level (-20 dB: 10 %), the
largest drive a controller may command before the driver's nonlinearity dominates the ear signal.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import scipy.optimize

from ..core.model import Model

__all__ = ["harmonic_levels", "saturation_form", "tanh_map", "drive_limit", "DRIVE_LIMIT_DB"]

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
        levels = harmonic_levels(model.apply_input_nonlinearity, amplitude, range(2, 10))
        return 10 * np.log10(sum(10 ** (v / 10) for v in levels.values()))

    grid = np.geomspace(1e-4, largest, int(48 * np.log10(largest / 1e-4)) + 1)
    above = [k for k, a in enumerate(grid) if distortion(a) >= level_db]
    if not above:
        return None
    k = above[0]
    if k == 0:
        return float(grid[0])
    return float(scipy.optimize.brentq(lambda a: distortion(a) - level_db, grid[k - 1], grid[k], xtol=1e-9))
