"""Filtered-x LMS feed-forward adaptation, simulated sample by sample: the peer W is compared with.

W is an FIR of ``taps`` coefficients w acting on the chin reference, the drive
y[k] = sum_i w_i x[k - L - i] reaches the ear through the TRUE path S, and the update
uses the reference filtered by the secondary-path MODEL (Widrow & Stearns, "Adaptive Signal
Processing", 1985, ch. 11; Elliott, "Signal Processing for Active Control", 2001, sec. 3.4),
normalised by the filtered-reference power:

.. math::
    w \\leftarrow w - \\bar\\mu \\, e[k] \\, r_k / (r_k^T r_k + \\epsilon), \\qquad
    r[k] = (z^{-L} S_{model} x)[k].

Step size (``stable_step``): with a secondary path of delay Delta samples the FxLMS step is stable
for mu < 2 / (P_r (I + Delta)) (I taps, P_r the filtered reference's power; Elliott 2001, sec. 3.4,
after Elliott, Stothers & Nelson 1987), which in the normalised form (mu_bar = mu I P_r) reads
mu_bar < 2 I / (I + Delta). ``run_to_convergence`` starts at half that bound (``STEP_FRACTION``), the
usual choice between speed and misadjustment, with Delta the latency plus the delay to the largest
sample of S_model's impulse response (``secondary_delay``). The bound assumes a white reference and a
path that is a pure delay; a path with a slow pole (the seed's FB path: 0.99991, 12000 samples' time
constant) and a pink reference are unstable well below it (the seed pair diverges at mu_bar 3e-4 with
64 taps against a bound of 1.5), so a run that diverges (``diverging``) is run again at a quarter of
its step, at most ``MAX_REDUCTIONS`` times; the result states the step used and the bound.

Convergence (``convergence``): the ear attenuation per frame (``FRAME_S``) has converged when the
slope of a straight line through the last ``TAIL_FRACTION`` of the run is within two of its
standard errors of zero (the slope is within the frames' noise); the converged attenuation is the
mean over that tail and the time to reach it the first frame from which the smoothed attenuation
stays within 1 dB of it. A run that has not converged is reported as such, never as a figure.
``run_until_converged`` runs again on a noise record twice as long (from the start, the step chosen again)
until it converges or reaches its longest record: an FxLMS whose slow modes take tens of seconds (the seed's
FB pole at 0.99991) is judged at its fixed point, not where a fixed record happens to end.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sysid.core.model import Model

__all__ = ["FxlmsRun", "FxlmsResult", "run_fxlms", "convergence", "stable_step", "secondary_delay",
           "run_to_convergence", "run_until_converged", "diverging", "STEP_FRACTION", "FRAME_S", "TAIL_FRACTION",
           "MAX_REDUCTIONS"]

STEP_FRACTION = 0.5
MAX_REDUCTIONS = 6
FRAME_S = 0.1
TAIL_FRACTION = 0.25
# Samples of S_model's impulse response searched for its largest sample (secondary_delay).
_IMPULSE_SAMPLES = 4096


@dataclass
class FxlmsRun:
    """Ear signal ``e`` with adaptation, disturbance ``d``, final coefficients ``w``, the step ``mu`` (normalised)."""

    e: np.ndarray
    d: np.ndarray
    w: np.ndarray
    mu: float = 0.0


@dataclass(frozen=True)
class FxlmsResult:
    """``attenuation_db`` over the converged tail (dB, positive = quieter), ``seconds`` to come within 1 dB of it,
    ``converged`` (the tail's slope within its noise), ``slope_db_per_s`` and its standard error, the step
    ``mu`` and its stability bound ``mu_bound`` (normalised), ``run_seconds`` simulated."""

    attenuation_db: float
    seconds: float
    converged: bool
    slope_db_per_s: float
    slope_error_db_per_s: float
    mu: float
    mu_bound: float
    run_seconds: float


def secondary_delay(s_model: Model, latency: int) -> int:
    """Delta (samples): the latency plus where S_model's impulse response has its largest sample."""
    impulse = np.zeros(_IMPULSE_SAMPLES)
    impulse[0] = 1.0
    return int(latency + np.argmax(np.abs(s_model.simulate(impulse))))


def stable_step(taps: int, delay_samples: int) -> float:
    """The normalised FxLMS step's stability bound 2 I / (I + Delta) (module docstring)."""
    return 2.0 * taps / (taps + max(delay_samples, 0))


def run_fxlms(s_true: Model, s_model: Model, x: np.ndarray, d: np.ndarray, latency: int = 2, taps: int = 128,
              mu: float = 0.5) -> FxlmsRun:
    """Simulate normalised FxLMS (module docstring) with normalised step ``mu``; x chin reference, d ear noise
    without control. A diverging run stops growing at 1e6 times the disturbance's peak (then stays there)."""
    n = d.size
    r = s_model.simulate(np.concatenate((np.zeros(latency), x[: n - latency])))
    xl = np.concatenate((np.zeros(latency), x[: n - latency]))
    # Reversed buffers so that a slice [k + taps - 1 - i] is x[k - i].
    xbuf = np.concatenate((np.zeros(taps - 1), xl))
    rbuf = np.concatenate((np.zeros(taps - 1), r))
    A, B, C, D = s_true.A, s_true.B[:, 0], s_true.C[0], float(s_true.D[0, 0])
    delay = s_true.delay
    state = np.zeros(s_true.order)
    w = np.zeros(taps)
    y = np.zeros(n)
    e = np.zeros(n)
    eps = 1e-6 * float(np.mean(r**2) * taps + 1e-30)
    ceiling = 1e6 * max(float(np.max(np.abs(d))), 1e-30)
    for k in range(n):
        y[k] = w @ xbuf[k: k + taps][::-1]
        v = y[k - delay] if k >= delay else 0.0
        e[k] = d[k] + C @ state + D * v
        if not abs(e[k]) < ceiling:
            e[k:] = ceiling
            break
        state = A @ state + B * v
        rk = rbuf[k: k + taps][::-1]
        w -= mu * e[k] * rk / (rk @ rk + eps)
    return FxlmsRun(e, d, w, mu)


def convergence(run: FxlmsRun, fs: float, frame_s: float = FRAME_S) -> tuple[float, float, bool, float, float]:
    """(attenuation over the tail in dB, seconds to come within 1 dB of it, converged, slope dB/s, its standard
    error) of a run (module docstring)."""
    hop = max(int(frame_s * fs), 1)
    frames = run.d.size // hop
    d = run.d[: frames * hop].reshape(frames, hop)
    e = run.e[: frames * hop].reshape(frames, hop)
    with np.errstate(over="ignore", invalid="ignore"):
        att = 10 * np.log10(np.sum(d**2, axis=1) / np.maximum(np.sum(e**2, axis=1), 1e-300))
    tail = max(int(round(TAIL_FRACTION * frames)), 4)
    t = np.arange(frames)[-tail:] * frame_s
    slope, intercept = np.polyfit(t, att[-tail:], 1)
    residual = att[-tail:] - (slope * t + intercept)
    error = float(np.sqrt(np.sum(residual**2) / max(tail - 2, 1) / np.sum((t - t.mean()) ** 2)))
    final = float(np.mean(att[-tail:]))
    converged = bool(np.all(np.isfinite(att[-tail:])) and abs(slope) <= 2.0 * error and final > -60.0)
    smooth = np.convolve(att, np.ones(3) / 3, mode="same")
    outside = np.nonzero(np.abs(smooth[:-tail] - final) > 1.0)[0]
    start = 0 if outside.size == 0 else int(outside[-1]) + 1
    return final, start * frame_s, converged, float(slope), error


def diverging(result: FxlmsResult) -> bool:
    """The ear is getting louder: louder than without control and the tail's slope below zero beyond its noise,
    or the run stopped at its ceiling."""
    return result.attenuation_db < -60.0 or (result.attenuation_db < 0.0
                                              and result.slope_db_per_s < -2.0 * result.slope_error_db_per_s)


def run_to_convergence(s_true: Model, s_model: Model, x: np.ndarray, d: np.ndarray, latency: int = 2,
                       taps: int = 128, mu: float | None = None) -> tuple[FxlmsRun, FxlmsResult]:
    """Run FxLMS over the given signals and judge it (module docstring): at ``mu`` if given, else from
    ``STEP_FRACTION`` of ``stable_step``, a quarter of the step again while the run diverges."""
    bound = stable_step(taps, secondary_delay(s_model, latency))
    steps = [mu] if mu is not None else [STEP_FRACTION * bound * 0.25 ** i for i in range(MAX_REDUCTIONS + 1)]
    for step in steps:
        run = run_fxlms(s_true, s_model, x, d, latency, taps, step)
        final, seconds, converged, slope, error = convergence(run, s_true.fs)
        result = FxlmsResult(final, seconds, converged, slope, error, float(step), float(bound), d.size / s_true.fs)
        if not diverging(result):
            break
    return run, result


def run_until_converged(s_true: Model, s_model: Model, noise: Callable[[float], tuple[np.ndarray, np.ndarray]],
                        seconds: float, longest_s: float, latency: int = 2,
                        taps: int = 128) -> tuple[FxlmsRun, FxlmsResult]:
    """``run_to_convergence`` on ``noise(seconds)`` (chin reference x, ear noise d, each ``seconds`` long), the
    record doubled while the run has not converged and is shorter than ``longest_s`` (module docstring)."""
    while True:
        x, d = noise(seconds)
        run, result = run_to_convergence(s_true, s_model, x, d, latency, taps)
        if result.converged or 2.0 * seconds > longest_s:
            return run, result
        seconds *= 2.0
