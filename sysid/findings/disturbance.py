"""Periodic disturbance: spectral lines in the residual that are not in the input (effects.md).

The model's residual on the noise recording (after the transient) is Hann-windowed
and transformed in one piece; a line is a bin more than ``LINE_RATIO`` times the
median of its neighbourhood (for noise the periodogram is exponentially
distributed, so chance exceedances are of order exp(-LINE_RATIO ln 2)) while the
input spectrum has no line there. Frequencies are refined by parabolic
interpolation of the log spectrum around the peak (for a Hann window the bias is
below a tenth of a bin), and each line must also be present in both sweep residuals.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage

from ..compare import fit_sinusoids
from ..thresholds import IDENTIFICATION_BAND
from ..validation import SKIP_S
from . import DiagnosisContext, finding, noise_prediction
from .dynamics import factor_residual, has_series_factor, within_resonance

__all__ = ["disturbance_finding", "find_lines"]

LINE_RATIO = 40.0
MAX_LINES = 12
NEIGHBOURHOOD_HZ = 20.0


def find_lines(x: np.ndarray, u: np.ndarray, fs: float, band=IDENTIFICATION_BAND, known=()) -> list[tuple[float, float, float]]:
    """(frequency Hz, ratio to neighbourhood, RMS level FS) of the lines of x that u lacks."""
    n = x.size
    window = np.hanning(n)
    f = np.fft.rfftfreq(n, 1 / fs)
    width = max(9, int(NEIGHBOURHOOD_HZ * n / fs) | 1)
    # Only the band and half a neighbourhood around it: the median filter is the costly step.
    lo = max(int(np.searchsorted(f, band[0])) - width, 1)
    hi = min(int(np.searchsorted(f, band[1])) + width, f.size - 1)
    X = np.zeros(f.size)
    X[lo - 1:hi + 1] = (np.abs(np.fft.rfft((x - x.mean()) * window)) ** 2)[lo - 1:hi + 1]
    Uu = (np.abs(np.fft.rfft((u - u.mean()) * window)) ** 2)[lo:hi]
    background = scipy.ndimage.median_filter(X[lo:hi], size=width, mode="nearest")
    background_u = scipy.ndimage.median_filter(Uu, size=width, mode="nearest")
    ratio = np.zeros(f.size)
    ratio_u = np.zeros(f.size)
    ratio[lo:hi] = X[lo:hi] / np.maximum(background, 1e-300)
    ratio_u[lo:hi] = Uu / np.maximum(background_u, 1e-300)
    inside = (f >= band[0]) & (f <= band[1])
    peaks = np.where(inside[1:-1] & (ratio[1:-1] > LINE_RATIO) & (X[1:-1] >= X[:-2]) & (X[1:-1] >= X[2:])
                     & (ratio_u[1:-1] < LINE_RATIO / 4))[0] + 1
    peaks = peaks[np.argsort(ratio[peaks])[::-1]][:MAX_LINES]
    lines = []
    for k in peaks:
        a, b, c = np.log(X[k - 1:k + 2] + 1e-300)
        offset = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 else 0.0
        frequency = (k + float(np.clip(offset, -0.5, 0.5))) * fs / n
        if any(abs(frequency - g) < 2 * fs / n for g in known):
            continue
        # The level from 2 s of the recording: plenty for a line this far above the noise.
        excerpt = x[: int(2 * fs)] - x.mean()
        fitted = fit_sinusoids(excerpt, [frequency], fs)
        lines.append((frequency, float(ratio[k]), float(np.sqrt(np.mean(fitted**2)))))
    return sorted(lines)


def _in_sweep(residual: np.ndarray, frequency: float, fs: float) -> bool:
    """Is a sinusoid at frequency in the residual, beyond 5 standard errors of its amplitude?"""
    fitted = fit_sinusoids(residual, [frequency], fs)
    level = np.sqrt(np.mean(fitted**2))
    # Four columns per line: the fitted RMS of pure noise is about sigma sqrt(4 / N).
    return level > 5.0 * np.std(residual - fitted) * np.sqrt(4.0 / residual.size)


def disturbance_finding(ctx: DiagnosisContext) -> dict:
    model = ctx.model
    body_start = int(round(ctx.transient_s * ctx.fs))
    # What a significant series factor leaves: a lightly damped mode the model lacks rings like a line.
    prediction = noise_prediction(ctx)
    residual = factor_residual(ctx, ctx.noise.y - prediction, prediction)[body_start:]
    u = ctx.noise.u[body_start:]
    candidates = [line for line in find_lines(residual, u, ctx.fs, known=model.disturbance_frequencies or ())
                  if not within_resonance(ctx, line[0])]
    first = int(round(SKIP_S * ctx.fs))
    sweep_residuals = [s["residual"] for s in ctx.comparison.per_sweep]
    if candidates and has_series_factor(ctx):
        sweep_residuals = [factor_residual(ctx, s["residual"], s["linear"]) for s in ctx.comparison.per_sweep]
    lines = [line for line in candidates if all(_in_sweep(r[first:], line[0], ctx.fs) for r in sweep_residuals)]
    significant = bool(lines)
    frequencies = [round(line[0], 3) for line in lines]
    levels = [line[2] for line in lines]
    score = max((np.log10(line[1]) / np.log10(LINE_RATIO) for line in lines), default=0.0)
    if lines:
        fundamental = min(frequencies)
        harmonic = all(abs(f / fundamental - round(f / fundamental)) < 0.01 for f in frequencies)
        origin = ("mains hum" if abs(fundamental - 50) < 1 or abs(fundamental - 60) < 1
                  else f"an engine order (single cylinder at {fundamental * 120:.0f} rpm)" if fundamental < 200
                  else "a periodic source")
        explanation = (f"{len(lines)} line(s) in the residual at {', '.join(f'{f:.2f}' for f in frequencies)} Hz "
                       f"(strongest {20 * np.log10(max(line[1] for line in lines)):.0f} dB above the noise around it), "
                       f"absent from the input and present in every recording: "
                       f"{origin}{' with harmonics' if harmonic and len(lines) > 1 else ''}; not part of the plant")
    else:
        explanation = "no spectral line in the residual that the input lacks"
    return finding("periodic-disturbance", significant, score, {"frequencies_hz": frequencies, "levels_fs": levels},
                   explanation,
                   "refine --add periodic-disturbance:frequencies_hz=" + "/".join(f"{f:g}" for f in frequencies)
                   if lines else "none", {"candidates": len(candidates)})
