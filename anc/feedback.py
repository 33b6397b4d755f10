"""Feedback filter Q for internal model control, robust against the model's uncertainty.

With the runtime's disturbance observer d_hat = e - S_model y and y[k] = Q d_hat[k-L],
a perfect model gives e = (1 + G Q) d with G = z^-L S_model (the loop is open: d_hat = d);
a model error Delta = S - S_model closes a loop y = z^-L Q (d + Delta y), stable whenever
|Delta Q| < 1 at every frequency (small-gain theorem).

Criterion (``design_feedback``): over Q in the Laguerre family (``anc.basis``) minimise the
disturbance-weighted expected ear power

.. math::
    J(Q) = \\sum_k \\Phi_d(f_k) \\left( |1 + G Q|^2 + s^2 |G Q|^2 \\right),
    \\qquad s = r_{95} / 1.73,

(s the RMS relative model error: a complex Gaussian error exceeds 1.73 times its RMS
with probability 5 %) subject to

* robust stability with margin 2: r_95(f) |S_model(f)| |Q(f)| <= 0.5 at every frequency,
* a bounded waterbed: |1 + G Q| <= ``max_amplification_db`` (default 6 dB).

The constraints are imposed by iteratively reweighting a penalty on |Q|^2 (robustness) and
the weight on |1 + G Q|^2 (amplification) where they are violated, then guaranteed for the
robustness bound by scaling Q down if a violation is left on the grid.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sysid.core.model import Model

from .basis import LaguerreBasis, fit
from .disturbance import Disturbance
from .uncertainty import Uncertainty

__all__ = ["FeedbackDesign", "design_feedback", "dense_grid", "loop_margins", "ROBUSTNESS_BOUND", "RMS_PER_95"]

ROBUSTNESS_BOUND = 0.5
RMS_PER_95 = 1.0 / np.sqrt(np.log(20.0))
_ITERATIONS = 40


@dataclass
class FeedbackDesign:
    """Q = basis with ``coefficients``; responses on ``frequencies_hz``; margins and notes (why it is as it is)."""

    basis: LaguerreBasis
    coefficients: np.ndarray
    frequencies_hz: np.ndarray
    loop: np.ndarray           # G Q = z^-L S_model Q
    relative_95: np.ndarray    # r_95 on the grid
    margins: dict = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def sensitivity(self) -> np.ndarray:
        """1 + G Q: ear noise with control over ear noise without (nominal model)."""
        return 1.0 + self.loop


def design_grid(fs: float, points: int = 4096) -> np.ndarray:
    """Design grid (Hz): DC, 32 log-spaced points from 0.5 Hz, then uniform from fs / (2 points) to fs / 2.

    The uniform part is fine enough for 20 Hz bands at 48 kHz; the points below it hold Q's
    gain near DC, where the model is an extrapolation and a loop can drift unstable.
    """
    uniform = np.linspace(fs / (2 * points), fs / 2.0, points)
    return np.concatenate(([0.0], np.geomspace(0.5, uniform[0], 33)[:-1], uniform))


def dense_grid(model: Model, bins: int = 8192) -> np.ndarray:
    """Frequencies (Hz) on which the stored Q's robustness is verified (``anc.design``): every bin of
    a 2 * ``bins``-point FFT (fs / 16384 apart: 2.9 Hz at 48 kHz, twice the design grid's density),
    ``bins`` log-spaced points from 0.1 Hz (0.15 % apart) and, around each pole of the
    model, 41 points spanning +-4 half-power bandwidths (|ln r| fs / pi each; at least 1e-6 Hz),
    where a lightly damped mode's peak lies between the bins (design grid: fs / 8192 apart), and
    the design grid itself."""
    fs = model.fs
    # Log-spaced points as well: below a few tens of hertz the bound where nothing is known
    # (``anc.uncertainty``) changes faster than the bins resolve (0.5004 at 7.91 Hz on the seed
    # between bins that saw 0.5).
    points = [np.linspace(0.0, fs / 2.0, bins + 1), np.geomspace(0.1, fs / 2.0, bins)]
    if model.order:
        poles = np.linalg.eigvals(model.A)
        poles = poles[np.abs(poles) > 0]
        centre = np.abs(np.angle(poles)) * fs / (2.0 * np.pi)
        width = np.maximum(np.abs(np.log(np.abs(poles))) * fs / np.pi, 1e-6)
        points.append((centre[:, None] + 4.0 * width[:, None] * np.linspace(-1.0, 1.0, 41)[None, :]).reshape(-1))
    f = np.concatenate(points + [design_grid(fs)])
    return np.unique(f[(f >= 0.0) & (f <= fs / 2.0)])


def loop_margins(loop: np.ndarray, frequencies_hz: np.ndarray, relative_95: np.ndarray, s_model_q: np.ndarray) -> dict:
    """Margins of the equivalent one-degree-of-freedom loop and the robustness figures.

    The IMC law equals the feedback controller K = z^-L Q / (1 + z^-L Q S_model) on e;
    its loop gain (negative-feedback convention, e = d / (1 + Lg)) is
    Lg = -S K = -G Q / (1 + G Q) on the nominal model. Gain margin: 1/|Lg| where Lg crosses
    the negative real axis (inf if never); phase margin: 180 deg + arg Lg where |Lg| = 1
    (180 if never); peak amplification: max 20 log10 |1 + G Q|; robustness factor:
    min 0.5 / (r_95 |S_model Q|) (> 1: the stated uncertainty is met with margin).
    """
    Lg = -loop / (1.0 + loop)
    gm = np.inf
    crossing = np.nonzero((np.sign(Lg.imag[:-1]) != np.sign(Lg.imag[1:])) & (Lg.real[:-1] < 0))[0]
    for i in crossing:
        t = Lg.imag[i] / (Lg.imag[i] - Lg.imag[i + 1])
        value = Lg[i] + t * (Lg[i + 1] - Lg[i])
        if value.real < 0:
            gm = min(gm, 1.0 / abs(value.real))
    pm = 180.0
    magnitude = np.abs(Lg)
    for i in np.nonzero(np.sign(magnitude[:-1] - 1.0) != np.sign(magnitude[1:] - 1.0))[0]:
        pm = min(pm, 180.0 - abs(np.degrees(np.angle(Lg[i]))))
    amplification = 20.0 * np.log10(np.abs(1.0 + loop))
    peak = int(np.argmax(amplification))
    usage = relative_95 * np.abs(s_model_q)
    return {
        "gain_margin_db": float(20.0 * np.log10(gm)) if np.isfinite(gm) else None,
        "phase_margin_deg": float(pm),
        "peak_amplification_db": float(amplification[peak]),
        "peak_amplification_hz": float(frequencies_hz[peak]),
        "robustness_factor": float(ROBUSTNESS_BOUND / max(np.max(usage), 1e-300)),
    }


def _ranges(frequencies_hz: np.ndarray, mask: np.ndarray) -> str:
    """'600-2000 Hz, 5000-22050 Hz' for the runs where mask is true."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(int), [0]))))
    return ", ".join(f"{frequencies_hz[a]:.0f}-{frequencies_hz[b - 1]:.0f} Hz" for a, b in zip(edges[::2], edges[1::2]))


def design_feedback(s_model: Model, disturbance: Disturbance, latency: int, uncertainty: Uncertainty,
                    basis: LaguerreBasis, max_amplification_db: float = 6.0) -> FeedbackDesign:
    """Robust IMC feedback filter Q for the model s_model (criterion: module docstring)."""
    fs = s_model.fs
    # The design grid plus 160 log-spaced points 0.5-200 Hz (2.3 % apart), where the bound where
    # nothing is known changes faster than the uniform step and jumps at the stated band's lower
    # edge (between grid points the seed's Q reached 0.77 at 19.5 Hz and 0.536 at 7.8 Hz without
    # them). They carry the bounds only: the criterion's sum stays the design grid's. (Points just
    # either side of the edge as well gave the seed a Q with a notch at 20 Hz whose float32
    # coefficients codegen refuses: 27.8 dB SNR against 30.)
    low = np.geomspace(0.5, 200.0, 160)
    grid = design_grid(fs)
    f = np.unique(np.concatenate((grid, low)))
    G = s_model.frequency_response(f) * np.exp(-2j * np.pi * f * latency / fs)
    phi = np.maximum(disturbance.at(f).ear_psd, 0.0)
    phi = (phi + 1e-6 * phi.max()) * np.isin(f, grid)
    r95 = uncertainty.at(f)
    s2 = (r95 * RMS_PER_95) ** 2
    basis_f = basis.responses(f, fs)
    bound = 10.0 ** (max_amplification_db / 20.0)
    scale = float(np.sum(phi * np.abs(G) ** 2) / grid.size)
    weight = phi.copy()
    robust_penalty = np.zeros_like(f)
    for _ in range(_ITERATIONS):
        c = fit(basis_f, G, np.ones_like(G), weight, phi * s2 * np.abs(G) ** 2 + robust_penalty + 1e-9 * scale)
        Q = basis_f @ c
        usage = r95 * np.abs(G * Q) / ROBUSTNESS_BOUND
        amplification = np.abs(1.0 + G * Q) / bound
        if usage.max() <= 1.0 and amplification.max() <= 1.0:
            break
        # Raise the penalty where a bound is broken (by the square of the excess, twice over:
        # the fit then moves most of the way to the bound in one step).
        over = usage > 1.0
        robust_penalty[over] = np.maximum(robust_penalty[over], 1e-3 * scale) * usage[over] ** 4
        over = amplification > 1.0
        weight[over] = np.maximum(weight[over], 1e-3 * phi.max()) * amplification[over] ** 4
    notes = []
    excess = usage.max()
    if excess > 1.0:
        c = c / excess
        Q = basis_f @ c
        notes.append(f"Q scaled by {1 / excess:.3f} so that r95 |S_model Q| <= {ROBUSTNESS_BOUND} on the whole grid")
    loop = G * Q
    usage = r95 * np.abs(loop) / ROBUSTNESS_BOUND
    outside = (f < uncertainty.band_hz[0]) | (f > uncertainty.band_hz[1])
    peak = "" if uncertainty.peak is None else f" (peak {uncertainty.peak:.3g})"
    if np.any(outside):
        notes.append(f"outside the model's stated band {uncertainty.band_hz[0]:.0f}-{uncertainty.band_hz[1]:.0f} Hz "
                     f"({uncertainty.source}) nothing is known of S: only a gain no larger than the model vouches for "
                     f"in band{peak}, growing at most as 1/f below it, is assumed, and |Q| <= 0.5 / (|S_model| + that "
                     "gain) there")
    unreliable = uncertainty.unknown(f) & ~outside
    if np.any(unreliable):
        notes.append("conservative where the model's stated 95 % error reaches 100 % (the band is a first-order bound "
                     "and no bound there; feedback does almost nothing) at " + _ranges(f, unreliable))
    active = usage > 0.9
    if np.any(active):
        notes.append("robustness bound active (gain limited by the model's uncertainty) at " + _ranges(f, active))
    margins = loop_margins(loop, f, r95, loop)
    return FeedbackDesign(basis, c, f, loop, r95, margins, notes)
