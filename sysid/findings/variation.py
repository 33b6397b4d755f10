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

from ..core.thresholds import DRIFT_PPM, DRIFT_T, EXCESS, IDENTIFICATION_BAND, SKIP_S, VALIDATION_BAND, VARIATION_RATIO
from ..core.thresholds import VARIATION_CHANGE_DB as CHANGE_DB
from ..core.thresholds import VARIATION_CHANGE_T as CHANGE_T
from ..core.thresholds import VARIATION_LOW_HZ as LOW_HZ
from ..io.data_quality import clipped_samples
from ..io.lines import without_lines
from ..validation.compare import third_octave_bands
from . import DiagnosisContext, finding, provider, uses

__all__ = ["segment_responses", "clock_drift_finding", "time_variation_finding", "recording_change",
           "recording_levels"]

SEGMENTS = 8
NPERSEG = 4410  # 10 Hz resolution: about 28 bins below 300 Hz for the time-variation ratio


def segment_responses(ctx: DiagnosisContext):
    """(frequencies, H1 per segment [S x F], coherence per segment, segment centres in samples): the
    shared value ``segments``."""
    return ctx.value("segments")


@provider("segments")
def _segment_responses(ctx: DiagnosisContext):
    # Without the lines the model knows (``lines.without_lines``): a hum is no response to the input, and
    # on a quiet noise recording it moves the segments' H1 below 300 Hz (random helmet 100 FF, 60 Hz at
    # 9.9e-4 FS under an ear signal of 0.024 FS peak: noise vs sweeps 0.52 dB with it, 0.08 dB without).
    body = without_lines(ctx.body, ctx.model.disturbance_frequencies)
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
    return f, np.array(responses), np.array(coherences), np.array(centres)


@uses("segments")
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


def recording_levels(ctx: DiagnosisContext) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """(band centres Hz, response level in dB per band for each recording, standard error of the noise
    recording's levels in dB) on third-octave bands 20 Hz - 4 kHz.

    The noise recording's level is the mean over its segments' H1 (``segment_responses``),
    its standard error the spread of the segments over sqrt(SEGMENTS); a sweep's is the median
    over the band's DFT bins of |Y/U| where the sweep excites the band (|U| within 20 dB of its
    largest bin there).
    """
    f, H, coherence, _ = segment_responses(ctx)
    segment_db = 20 * np.log10(np.abs(H) + 1e-300)
    centres, noise_level, noise_error, sweep_levels = [], [], [], {s.path: [] for s in ctx.sweeps}
    spectra = []
    first = int(round(SKIP_S * ctx.fs))
    for sweep, record in zip(ctx.sweeps, ctx.comparison.per_sweep):
        # The model's excluded (clipped) stretches hold the clipper's levels, not the path's: there the
        # model's prediction stands in, as in the comparison.
        y = np.where(record["excluded"], record["predicted"], record["measured"])
        U, Y = np.fft.rfft(sweep.u[first:]), np.fft.rfft(y[first:])
        spectra.append((np.fft.rfftfreq(sweep.u.size - first, 1 / ctx.fs), U, Y))
    for centre, low, high in third_octave_bands(*VALIDATION_BAND):
        use = (f >= low) & (f < high) & np.all(coherence > 0.5, axis=0)
        if np.count_nonzero(use) < 1:
            continue
        levels = segment_db[:, use].mean(axis=1)
        centres.append(centre)
        noise_level.append(levels.mean())
        noise_error.append(levels.std(ddof=1) / np.sqrt(levels.size))
        for sweep, (fs_bins, U, Y) in zip(ctx.sweeps, spectra):
            inside = (fs_bins >= low) & (fs_bins < high)
            strong = inside & (np.abs(U) > 0.1 * np.max(np.abs(U[inside]), initial=0.0))
            sweep_levels[sweep.path].append(float(np.median(20 * np.log10(np.abs(Y[strong] / U[strong]) + 1e-300)))
                                            if np.any(strong) else np.nan)
    levels = {ctx.noise.path: np.array(noise_level), **{k: np.array(v) for k, v in sweep_levels.items()}}
    return np.array(centres), levels, np.array(noise_error)


def recording_change(ctx: DiagnosisContext) -> dict:
    """Whether the path changed between recordings: noise recording vs each sweep, sweep 1 vs sweep 2.

    A changed fit or leak moves the low band (below ``LOW_HZ``) against the band above it
    (effects.md: leak changes lie mostly below 200-300 Hz). Comparing the shape (low band
    minus mid band, in dB) makes the test blind to a broadband gain bias of one estimate
    (the H1 bias of input noise, a level-dependent gain). Each pair's shape difference
    must exceed ``CHANGE_DB`` and ``CHANGE_T`` standard errors; the recording that differs
    from both others is the one that disagrees. The noise recording is named only when the
    model is ``EXCESS`` above the floor on the sweeps (see the comment below).
    """
    centres, levels, error = recording_levels(ctx)
    low, mid = centres < LOW_HZ, (centres >= LOW_HZ) & (centres <= 2000.0)
    names = list(levels)
    # A clipped recording's levels are the clipper's, not the path's (the clipping finding names it, also
    # where a hum after the clipper hides the flat tops from the histogram).
    clipped = any(f["significant"] for f in ctx.findings_of("clipping")) or any(
        clipped_samples(x).fraction > 0 for r in (ctx.noise, *ctx.sweeps) for x in (r.u, r.y))
    if clipped or np.count_nonzero(low) < 2 or np.count_nonzero(mid) < 2:
        return {"changed": False, "pairs": {}, "odd_one_out": None, "change_db": 0.0}

    def shape(a, b):
        d = levels[a] - levels[b]
        return float(np.nanmedian(d[low]) - np.nanmedian(d[mid]))

    noise_error = float(np.sqrt(np.mean(error[low] ** 2) / np.count_nonzero(low) + np.mean(error[mid] ** 2)
                                / np.count_nonzero(mid)))
    pairs = {}
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            value = shape(a, b)
            # Sweep-to-sweep shapes carry hardly any estimation noise; the noise recording's does.
            spread = noise_error if names[0] in (a, b) else 0.0
            pairs[(a, b)] = (value, abs(value) >= max(CHANGE_DB, CHANGE_T * spread))
    odd = None
    for name in names:
        involved = [changed for pair, (_, changed) in pairs.items() if name in pair]
        others = [changed for pair, (_, changed) in pairs.items() if name not in pair]
        if all(involved) and not any(others):
            odd = name
    if odd == names[0] and ctx.excess < EXCESS:
        # The noise recording's levels are Welch H1 at 10 Hz resolution, which smooths lightly damped
        # modes below LOW_HZ by tenths of a dB that the sweeps' exact DFT does not (a clean random
        # helmet: 0.46 dB). A model of the noise recording that validates within EXCESS of the floor
        # on both sweeps shows the recordings agree where it matters; a real change (a re-seated
        # helmet) leaves that model far above the floor.
        odd = None
        pairs = {pair: (value, changed and names[0] not in pair) for pair, (value, changed) in pairs.items()}
    changed = odd is not None or all(c for _, c in pairs.values())
    change = max((abs(v) for v, c in pairs.values() if c), default=max(abs(v) for v, _ in pairs.values()))
    return {"changed": changed, "odd_one_out": odd, "change_db": change,
            "pairs": {f"{a} vs {b}": round(v, 3) for (a, b), (v, _) in pairs.items()}}


@uses("segments")
def time_variation_finding(ctx: DiagnosisContext) -> dict:
    """The path changing inside the noise recording, or between recordings (``recording_change``)."""
    across = recording_change(ctx)
    f, H, coherence, _ = segment_responses(ctx)
    level = 20 * np.log10(np.abs(H) + 1e-300)
    half = SEGMENTS // 2
    halves = level[:half].mean(axis=0) - level[half:].mean(axis=0)
    interleaved = level[0::2].mean(axis=0) - level[1::2].mean(axis=0)
    results = {}
    for name, band in (("low", (20.0, 300.0)), ("wide", IDENTIFICATION_BAND)):
        use = (f >= band[0]) & (f <= band[1]) & np.all(coherence > 0.5, axis=0)
        if np.count_nonzero(use) < 3:
            results[name] = (0.0, 0.0)
            continue
        # Medians keep a few disturbed bins (hum lines) from deciding the ratio.
        ratio = float(np.median(halves[use] ** 2) / max(np.median(interleaved[use] ** 2), 1e-30))
        results[name] = (ratio, float(np.sqrt(np.mean(halves[use] ** 2))))
    name = max(results, key=lambda key: results[key][0])
    ratio, change_db = results[name]
    # A change must also matter: below CHANGE_DB it moves the error of no model measurably.
    significant = ratio >= VARIATION_RATIO and change_db >= CHANGE_DB
    below = "below 300 Hz" if name == "low" else "across the band"
    if across["changed"] and not significant:
        odd = across["odd_one_out"]
        agree = [r.path for r in (ctx.noise, *ctx.sweeps) if r.path != odd]
        who = (f"{odd} disagrees with {' and '.join(agree)}" if odd else "all three recordings disagree")
        return finding("time-variation", True, max(across["change_db"] / CHANGE_DB, 1.0),
                       {"change_db": across["change_db"], "band": f"below {LOW_HZ:.0f} Hz against the band above",
                        "recording": odd, "agreeing": agree if odd else []},
                       f"the response below {LOW_HZ:.0f} Hz changed by {across['change_db']:.2f} dB between "
                       f"recordings: {who} (the helmet was re-seated or its leak changed between them)",
                       (f"identify from the recordings that agree ({', '.join(agree)}) or re-record {odd} with the "
                        "helmet as in the others" if odd else "re-record all three with the helmet fixed"),
                       {"pairs_db": across["pairs"], "ratio_low": results["low"][0]})
    explanation = (f"the response {below} changes by {change_db:.2f} dB RMS between the first and second half of the "
                   f"noise recording ({ratio:.1f}x the change between interleaved segments): the helmet's fit or "
                   "leak changed while recording"
                   if significant else "the first and second half of the noise recording agree within their noise")
    return finding("time-variation", significant, ratio / VARIATION_RATIO, {"change_db": change_db, "band": below},
                   explanation,
                   "identify per condition (re-record with the helmet fixed) and keep a nominal model plus an "
                   "uncertainty bound; no single model holds both halves" if significant else "none",
                   {"ratio_low": results["low"][0], "ratio_wide": results["wide"][0]})
