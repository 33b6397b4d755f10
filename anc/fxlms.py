"""Filtered-x LMS feed-forward adaptation, simulated sample by sample (the comparison for W).

W is an FIR of ``taps`` coefficients w acting on the chin reference, the drive
y[k] = sum_i w_i x[k - L - i] reaches the ear through the TRUE path S, and the update
uses the reference filtered by the secondary-path MODEL (Widrow & Stearns, "Adaptive Signal
Processing", 1985, ch. 11; Elliott 2001, sec. 3.4), normalised by the filtered-reference power:

.. math::
    w \\leftarrow w - \\mu \\, e[k] \\, r_k / (r_k^T r_k + \\epsilon), \\qquad
    r[k] = (z^{-L} S_{model} x)[k].

It converges (for small mu) to the FIR Wiener solution of ``anc.feedforward`` without its
bounds. ``run_fxlms`` returns the ear signal; ``convergence`` the converged attenuation and
the time to come within 1 dB of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sysid.core.model import Model

__all__ = ["FxlmsRun", "run_fxlms", "convergence"]


@dataclass
class FxlmsRun:
    """Ear signal ``e`` with adaptation, disturbance ``d``, final coefficients ``w``."""

    e: np.ndarray
    d: np.ndarray
    w: np.ndarray


def run_fxlms(s_true: Model, s_model: Model, x: np.ndarray, d: np.ndarray, latency: int = 1, taps: int = 128,
              mu: float = 5e-4) -> FxlmsRun:
    """Simulate normalised FxLMS (module docstring); x chin reference, d ear noise without control."""
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
    for k in range(n):
        y[k] = w @ xbuf[k: k + taps][::-1]
        v = y[k - delay] if k >= delay else 0.0
        e[k] = d[k] + C @ state + D * v
        state = A @ state + B * v
        rk = rbuf[k: k + taps][::-1]
        w -= mu * e[k] * rk / (rk @ rk + eps)
    return FxlmsRun(e, d, w)


def convergence(run: FxlmsRun, fs: float, window_s: float = 0.1) -> tuple[float, float]:
    """(converged attenuation in dB over the last 20 % of the run, seconds to come within 1 dB of it)."""
    hop = max(int(window_s * fs), 1)
    frames = run.d.size // hop
    d = run.d[: frames * hop].reshape(frames, hop)
    e = run.e[: frames * hop].reshape(frames, hop)
    att = 10 * np.log10(np.sum(d**2, axis=1) / np.maximum(np.sum(e**2, axis=1), 1e-300))
    tail = max(frames // 5, 1)
    final = float(10 * np.log10(np.sum(d[-tail:] ** 2) / max(np.sum(e[-tail:] ** 2), 1e-300)))
    # Smooth over 3 frames, then the first frame from which it stays within 1 dB.
    smooth = np.convolve(att, np.ones(3) / 3, mode="same")
    outside = np.nonzero(np.abs(smooth[:-tail] - final) > 1.0)[0]
    start = 0 if outside.size == 0 else int(outside[-1]) + 1
    return final, start * window_s
