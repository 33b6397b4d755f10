"""Changes along the noise recording: clock drift and time variation (effects.md).

The recording after its transient is cut into ``SEGMENTS`` equal parts with an H1
estimate (Welch, N = fs/20) each.

- clock-drift: the delay of segment k relative to the first is the slope of the
  unwrapped phase of H_k / H_1 over frequency (coherent bins, 20 Hz - 2 kHz);
  a delay that grows linearly with time is a sample-clock mismatch,
  ppm = 1e6 d(delay)/d(sample).
- time-variation: log-magnitude differences between the first and the second
  half, against those between interleaved segments (odd vs even), which see the
  same estimation noise but hardly any slow change. Their energy ratio is ~1 for
  a time-invariant path (an F statistic); a changing leak or fit raises it,
  mostly below a few hundred Hz.
"""

from __future__ import annotations

import numpy as np
import scipy.signal

from . import DiagnosisContext, finding

__all__ = ["segment_responses", "clock_drift_finding", "time_variation_finding"]

SEGMENTS = 8
NPERSEG = 4410  # 10 Hz resolution: about 28 bins below 300 Hz for the time-variation ratio
# Clock drift: at least this many ppm, with the trend this many standard errors from zero.
DRIFT_PPM, DRIFT_T = 3.0, 10.0
# Time variation: halves differ this many times more than interleaved segments (median over bins).
VARIATION_RATIO = 4.0


def segment_responses(ctx: DiagnosisContext):
    """(frequencies, H1 per segment [S x F], coherence per segment, segment centres in samples)."""
    if "segments" in ctx.cache:
        return ctx.cache["segments"]
    body = ctx.body
    length = body.u.size // SEGMENTS
    responses, coherences, centres = [], [], []
    for k in range(SEGMENTS):
        u = body.u[k * length:(k + 1) * length]
        y = body.y[k * length:(k + 1) * length]
        f, s_uu = scipy.signal.welch(u, ctx.fs, nperseg=NPERSEG)
        _, s_yy = scipy.signal.welch(y, ctx.fs, nperseg=NPERSEG)
        _, s_uy = scipy.signal.csd(u, y, ctx.fs, nperseg=NPERSEG)  # scipy: conj(U) Y
        responses.append(s_uy / s_uu)
        coherences.append(np.abs(s_uy) ** 2 / (s_uu * s_yy))
        centres.append((k + 0.5) * length)
    result = (f, np.array(responses), np.array(coherences), np.array(centres))
    ctx.cache["segments"] = result
    return result


def clock_drift_finding(ctx: DiagnosisContext) -> dict:
    f, H, coherence, centres = segment_responses(ctx)
    use = (f >= 20.0) & (f <= 2000.0) & np.all(coherence > 0.9, axis=0)
    delays = [0.0]
    if np.count_nonzero(use) >= 5:
        omega = 2 * np.pi * f[use] / ctx.fs
        for k in range(1, H.shape[0]):
            phase = np.unwrap(np.angle(H[k, use] / H[0, use]))
            # Delay tau adds phase -omega tau: least-squares slope through the origin.
            delays.append(float(-np.sum(omega * phase) / np.sum(omega**2)))
    delays = np.array(delays)
    ppm, t_stat = 0.0, 0.0
    if delays.size >= 3:
        slope, intercept = np.polyfit(centres[:delays.size], delays, 1)
        fitted = slope * centres[:delays.size] + intercept
        spread = np.sqrt(np.sum((delays - fitted) ** 2) / max(delays.size - 2, 1))
        centred = centres[:delays.size] - centres[:delays.size].mean()
        error = spread / np.sqrt(np.sum(centred**2)) if spread > 0 else 1e-30
        # A fast ear clock takes its sample k at input time k / (1 + eps): the ear signal lags more
        # and more, the delay grows by eps samples per sample. Positive ppm = ear clock fast.
        ppm = 1e6 * slope
        t_stat = abs(slope) / error
    significant = abs(ppm) >= DRIFT_PPM and t_stat >= DRIFT_T
    per_second = ppm * 1e-6 * ctx.fs
    explanation = (f"the delay changes linearly along the noise recording by {per_second:+.2f} samples/s: the ear "
                   f"channel's clock runs {abs(ppm):.1f} ppm {'fast' if ppm > 0 else 'slow'} against the input's "
                   f"({abs(ppm) * 1e-6 * 360 * 1500:.1f} deg/s of phase at 1.5 kHz)"
                   if significant else f"no delay trend along the recording ({ppm:.2f} ppm)")
    return finding("clock-drift", significant, min(abs(ppm) / DRIFT_PPM, t_stat / DRIFT_T),
                   {"ppm": ppm, "samples_per_second": per_second}, explanation,
                   "refine --add clock-drift (resamples the ear channel by the ratio "
                   f"{1 + ppm * 1e-6:.7f} and stores it in the model); better, record both channels from one clock"
                   if significant else "none",
                   {"segment_delays": [float(d) for d in delays], "t_statistic": t_stat})


def time_variation_finding(ctx: DiagnosisContext) -> dict:
    f, H, coherence, _ = segment_responses(ctx)
    level = 20 * np.log10(np.abs(H) + 1e-300)
    half = SEGMENTS // 2
    halves = level[:half].mean(axis=0) - level[half:].mean(axis=0)
    interleaved = level[0::2].mean(axis=0) - level[1::2].mean(axis=0)
    results = {}
    for name, band in (("low", (20.0, 300.0)), ("wide", (20.0, 5000.0))):
        use = (f >= band[0]) & (f <= band[1]) & np.all(coherence > 0.5, axis=0)
        if np.count_nonzero(use) < 3:
            results[name] = (0.0, 0.0)
            continue
        # Medians keep a few disturbed bins (hum lines) from deciding the ratio.
        ratio = float(np.median(halves[use] ** 2) / max(np.median(interleaved[use] ** 2), 1e-30))
        results[name] = (ratio, float(np.sqrt(np.mean(halves[use] ** 2))))
    name = max(results, key=lambda key: results[key][0])
    ratio, change_db = results[name]
    significant = ratio >= VARIATION_RATIO
    below = "below 300 Hz" if name == "low" else "across the band"
    explanation = (f"the response {below} changes by {change_db:.2f} dB RMS between the first and second half of the "
                   f"noise recording ({ratio:.1f}x the change between interleaved segments): the helmet's fit or "
                   "leak changed while recording"
                   if significant else "the first and second half of the noise recording agree within their noise")
    return finding("time-variation", significant, ratio / VARIATION_RATIO, {"change_db": change_db, "band": below},
                   explanation,
                   "identify per condition (re-record with the helmet fixed) and keep a nominal model plus an "
                   "uncertainty bound; no single model holds both halves" if significant else "none",
                   {"ratio_low": results["low"][0], "ratio_wide": results["wide"][0]})
