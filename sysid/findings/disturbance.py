"""Periodic disturbance: spectral lines in the residual that are not in the input (effects.md).

The lines of the model's residual on the noise recording that the input lacks
(``sysid.io.lines.find_lines``: more than ``LINE_RATIO`` times the median of their
neighbourhood; the session's one line search, the shared value ``session-lines`` of
``sysid.findings.data_quality``, which searches the noise recording first with the model's
own lines known) and does not explain (``sysid.io.lines.driven`` on the residual after the
transient: a mode the model lacks peaks in the residual too, coherent with the input), that are
stationary sinusoids there (``sysid.io.line_stationarity.is_stationary``: one phasor over the
residual's stretches; a mode rung by the drive's distortion products or by ambient noise peaks there
too, undriven by the linear input, but as a narrowband random process whose phase wanders at the
mode's bandwidth), each of which must also be present in both sweep residuals (beyond five
standard errors against the background beside the line, stretch by stretch:
``sysid.io.line_stationarity.line_significance``).
"""

from __future__ import annotations

import numpy as np

from ..core.thresholds import SKIP_S
from ..io.line_stationarity import is_stationary, line_significance
from ..io.lines import LINE_RATIO, driven, quiet_samples
from . import DiagnosisContext, finding, noise_prediction, uses
from .data_quality import session_line_search  # noqa: F401  (the provider of the shared value session-lines)
from .dynamics import factor_residual, has_series_factor, within_resonance

__all__ = ["disturbance_finding"]


def _in_sweep(residual: np.ndarray, frequency: float, fs: float) -> bool:
    """Is a sinusoid at frequency (Hz) in a sweep's residual, beyond 5 standard errors of its amplitude?

    The standard error from the background beside the line in each stretch of the sweep
    (``sysid.io.line_stationarity.line_significance``): the residual's error is where the sweep and its
    harmonics are, so its broadband rms (a distorted drive's harmonics at -15 dB) would bury a hum the
    quiet stretches show.
    """
    return line_significance(residual, frequency, fs) > 5.0**2


@uses("noise-prediction", "session-lines")
def disturbance_finding(ctx: DiagnosisContext) -> dict:
    body_start = int(round(ctx.transient_s * ctx.fs))
    # What a significant series factor leaves: a lightly damped mode the model lacks rings like a line.
    prediction = noise_prediction(ctx)
    residual = factor_residual(ctx, ctx.noise.y - prediction, prediction)[body_start:]
    u = ctx.noise.u[body_start:]
    # The noise recording's lines, searched first (with the model's lines known) by the session's search.
    peaks = [line for line in ctx.value("session-lines").found[0] if not within_resonance(ctx, line[0])]
    # A mode the model lacks or misplaces rings like a line in the residual, but the input explains it.
    undriven = [line for line, by_input in zip(peaks, driven(residual, u, ctx.fs, [p[0] for p in peaks])) if not by_input]
    # A hum keeps one amplitude and phase throughout; a mode rung by the drive's distortion (u^2 of the noise
    # through a Q-30 mode) or by ambient noise is not driven by the linear input either, but its phase wanders
    # at the mode's bandwidth. Fitted where the ear is not loud, as the line search does (clipped stretches).
    quiet = quiet_samples(ctx.noise.y)[body_start:]
    candidates = [line for line in undriven if is_stationary(residual, line[0], ctx.fs, quiet)]
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
                   if lines else "none", {"candidates": len(candidates), "not_stationary": len(undriven) - len(candidates)})
