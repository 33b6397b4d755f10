"""Feed-forward filter W from the chin reference: the causal Wiener solution in a Laguerre basis.

With d = H x + u (H = E[D X*] / E[X X*], the P model for the default spectrum; u not
coherent with x), the feedback loop 1 + G Q acting on d (see ``anc.feedback``;
Q = 0 without feedback) and G = z^-L S_model, the ear signal is
e = (1 + G Q) d + G W x. ``design_feedforward`` minimises, over causal stable W in the
basis, the expected ear power from the reference

.. math::
    J(W) = \\sum_k \\Phi_{xx} \\left( |G W + (1 + G Q) H|^2 + s^2 |G W|^2 \\right),

(s the RMS relative error of S_model, ``anc.feedback.RMS_PER_95``) subject to the gain
bound |W| <= ``max_gain_db`` and to a bounded amplification, |G W + (1 + G Q) H| <=
10^(``max_amplification_db`` / 20) |(1 + G Q) H| (the reference-coherent noise is never
made more than 6 dB louder where the reference is weak), both imposed by reweighting
(a penalty on |W|^2, the weight of the residual) where they are broken. Restricted to FIR filters this is the fixed point FxLMS converges to (Elliott,
"Signal Processing for Active Control", Academic Press 2001, sec. 3.3); the remainder
(1 + G Q) u is the incoherent part the coherence bound -10 log10(1 - coh^2) describes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sysid.model import Model

from .basis import LaguerreBasis, fit
from .disturbance import Disturbance
from .feedback import RMS_PER_95, design_grid
from .uncertainty import Uncertainty

__all__ = ["FeedforwardDesign", "design_feedforward"]

_ITERATIONS = 20


@dataclass
class FeedforwardDesign:
    """W = basis with ``coefficients``; ``notes`` say what limited it."""

    basis: LaguerreBasis
    coefficients: np.ndarray
    frequencies_hz: np.ndarray
    response: np.ndarray
    notes: list[str] = field(default_factory=list)


def design_feedforward(s_model: Model, disturbance: Disturbance, latency: int, uncertainty: Uncertainty,
                       basis: LaguerreBasis, feedback_loop=None, max_gain_db: float = 30.0,
                       max_amplification_db: float = 6.0) -> FeedforwardDesign:
    """Feed-forward W (criterion: module docstring). ``feedback_loop(f)`` returns G Q at f (Hz), or None."""
    fs = s_model.fs
    f = design_grid(fs)
    G = s_model.frequency_response(f) * np.exp(-2j * np.pi * f * latency / fs)
    spectra = disturbance.at(f)
    phi = np.maximum(spectra.reference_psd, 0.0)
    phi = phi + 1e-6 * phi.max()
    H = spectra.coherent_response()
    one_plus = 1.0 if feedback_loop is None else 1.0 + feedback_loop(f)
    s2 = (uncertainty.at(f) * RMS_PER_95) ** 2
    basis_f = basis.responses(f, fs)
    bound = 10.0 ** (max_gain_db / 20.0)
    scale = float(np.mean(phi * np.abs(G) ** 2))
    amplification_bound = 10.0 ** (max_amplification_db / 20.0)
    target = one_plus * H
    penalty = np.zeros_like(f)
    weight = phi.copy()
    for _ in range(_ITERATIONS):
        c = fit(basis_f, G, target, weight, phi * s2 * np.abs(G) ** 2 + penalty + 1e-9 * scale)
        W = basis_f @ c
        excess = np.abs(W) / bound
        amplification = np.abs(G * W + target) / np.maximum(amplification_bound * np.abs(target), 1e-300)
        if excess.max() <= 1.0 and amplification.max() <= 1.0:
            break
        over = excess > 1.0
        penalty[over] = np.maximum(penalty[over], 1e-3 * scale) * excess[over] ** 4
        over = amplification > 1.0
        weight[over] = np.maximum(weight[over], 1e-3 * phi.max()) * amplification[over] ** 4
    notes = []
    if np.abs(W).max() > bound:
        c = c * bound / np.abs(W).max()
        W = basis_f @ c
        notes.append(f"W scaled to the gain bound {max_gain_db:g} dB")
    return FeedforwardDesign(basis, c, f, W, notes)
