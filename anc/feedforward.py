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

Band rule (``BandRule``): a feed-forward filter has no waterbed, so W never makes a band
louder. In every third-octave band 20 Hz-2 kHz (``anc.prediction``, the bands the
attenuation is predicted in, summed over the same points) the predicted ear power with W is
at most ``BAND_TOLERANCE_DB`` (0.1 dB) above the power without it: W alone against no control,
and W with Q against Q alone. The criterion J alone does not give that: it is the ear power
over 0 - fs/2, and where P's response starts before that of z^-L S, W must predict the
reference and its error is broadband (random helmet 7: P's impulse response starts 2
samples before z^-L S's; 87 % of the chin-coherent ear power lies above 2 kHz; the
unconstrained W made a band 1.7 dB louder, and before the FF model's gain was capped outside
its band (``anc.disturbance``) its pole at fs/2 drew the fit there: -2.0 dB on average over
50 Hz - 1 kHz). The rule is imposed as convex quadratic constraints on the basis coefficients
(``BandRule.constraints``, ``anc.basis.fit``) on J with the final weights of the reweighting
above, and guaranteed by scaling W down to the largest factor in [0, 1] that keeps every
band inside it: a design that cannot help in a band leaves it (nearly) alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sysid.core.model import Model

from .basis import LaguerreBasis, fit
from .disturbance import Disturbance
from .feedback import RMS_PER_95, design_grid
from .prediction import band_grid
from .uncertainty import Uncertainty

__all__ = ["FeedforwardDesign", "design_feedforward", "BandRule", "BAND_TOLERANCE_DB"]

_ITERATIONS = 20
# A band may be this much louder with W than without (the rounding of a fit, not a trade; module docstring).
BAND_TOLERANCE_DB = 0.1
# The guarantee scales W to this fraction of the tolerance, so the stored (balanced) filter keeps it too.
_SCALE_MARGIN = 0.5


@dataclass
class FeedforwardDesign:
    """W = basis with ``coefficients``; ``notes`` say what limited it."""

    basis: LaguerreBasis
    coefficients: np.ndarray
    frequencies_hz: np.ndarray
    response: np.ndarray
    notes: list[str] = field(default_factory=list)


class BandRule:
    """The band rule (module docstring) on ``anc.prediction.band_grid()``: ear power per band with
    and without W, for W alone and with Q (``feedback_loop(f)`` = G Q, or None)."""

    def __init__(self, s_model: Model, disturbance: Disturbance, latency: int, feedback_loop=None):
        fs = s_model.fs
        grid = band_grid()
        self.shape = grid.shape
        self.frequencies_hz = grid.reshape(-1)
        f = self.frequencies_hz
        self.G = s_model.frequency_response(f) * np.exp(-2j * np.pi * f * latency / fs)
        spectra = disturbance.at(f)
        self.phi = np.maximum(spectra.reference_psd, 0.0)
        H = spectra.coherent_response()
        uu = spectra.incoherent_psd()
        one_plus = 1.0 if feedback_loop is None else 1.0 + feedback_loop(f)
        # Targets: W alone acts on H x, W with Q on (1 + G Q) H x; the powers without W (per band).
        self.targets = (H, one_plus * H)
        self.off = [self._sum(uu + self.phi * np.abs(H) ** 2),
                    self._sum(np.abs(one_plus) ** 2 * uu + self.phi * np.abs(one_plus * H) ** 2)]
        self.allowed = 10.0 ** (BAND_TOLERANCE_DB / 10.0) - 1.0

    def _sum(self, values: np.ndarray) -> np.ndarray:
        return np.sum(np.reshape(values, self.shape), axis=1)

    def _terms(self, W: np.ndarray):
        """Per case (alone, with Q) and band: the quadratic and linear coefficients of the power
        W adds, a |GW|^2 + 2 Re(GW T*), so that scaling W by t adds t^2 a + t b."""
        gw = self.G * W
        return [(self._sum(self.phi * np.abs(gw) ** 2), self._sum(2.0 * self.phi * np.real(gw * np.conj(T))))
                for T in self.targets]

    def excess_db(self, W: np.ndarray) -> np.ndarray:
        """(2, bands): 10 log10 of ear power with W over without it, W alone and with Q (dB, > 0 louder)."""
        return np.array([10.0 * np.log10(np.maximum(off + a + b, 1e-300) / np.maximum(off, 1e-300))
                         for off, (a, b) in zip(self.off, self._terms(W))])

    def holds(self, W: np.ndarray) -> bool:
        """Whether W (its response on ``frequencies_hz``) keeps every band within the tolerance."""
        return bool(np.all(self.excess_db(W) <= BAND_TOLERANCE_DB))

    def constraints(self, responses: np.ndarray, fraction: float = 1.0) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """The rule as quadratic constraints on real coefficients c of W = responses @ c (responses
        on ``frequencies_hz``): per case and band (A, b, limit) with c' A c + b' c <= limit =
        fraction * allowed, each divided by the band's power without W."""
        M = (self.G[:, None] * responses).reshape(self.shape + (-1,))
        phi = self.phi.reshape(self.shape)
        result = []
        for T, off in zip(self.targets, self.off):
            Tb = np.reshape(T, self.shape)
            for band in range(self.shape[0]):
                Mb = M[band]
                A = np.real((Mb.conj().T * phi[band]) @ Mb)
                b = 2.0 * np.real((phi[band] * np.conj(Tb[band])) @ Mb)
                # Divided by the power without W, so every constraint reads in fractions of its band's power.
                unit = max(float(off[band]), 1e-300)
                result.append((A / unit, b / unit, float(fraction * self.allowed)))
        return result

    def largest_scale(self, W: np.ndarray, fraction: float = 1.0) -> float:
        """Largest t in [0, 1] with t^2 a + t b <= fraction * allowed * off in every band and case."""
        t = 1.0
        for off, (a, b) in zip(self.off, self._terms(W)):
            c = fraction * self.allowed * off
            # t^2 a + t b - c <= 0 holds on [0, root] (a >= 0, c >= 0): root = (-b + sqrt(b^2 + 4 a c)) / 2a.
            with np.errstate(divide="ignore", invalid="ignore"):
                root = np.where(a > 0, (-b + np.sqrt(b * b + 4.0 * a * c)) / (2.0 * np.where(a > 0, a, 1.0)), np.inf)
            t = min(t, float(np.min(root)))
        return max(t, 0.0)


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
    rule = BandRule(s_model, disturbance, latency, feedback_loop)
    rule_basis = basis.responses(rule.frequencies_hz, fs)
    fitted = rule.excess_db(rule_basis @ c).max()
    if fitted > BAND_TOLERANCE_DB:
        # The same criterion (the last weights and penalties) with the band rule as constraints.
        c = fit(basis_f, G, target, weight, phi * s2 * np.abs(G) ** 2 + penalty + 1e-9 * scale,
                rule.constraints(rule_basis, _SCALE_MARGIN))
        W = basis_f @ c
    notes = []
    if np.abs(W).max() > bound:
        c = c * bound / np.abs(W).max()
        W = basis_f @ c
        notes.append(f"W scaled to the gain bound {max_gain_db:g} dB")
    if fitted > BAND_TOLERANCE_DB:
        notes.append(f"W fitted under the band rule: unconstrained it made a band {fitted:.2f} dB louder (the rule "
                     f"allows {BAND_TOLERANCE_DB:g} dB: W never makes a band 20 Hz-2 kHz louder, alone or with Q)")
    t = rule.largest_scale(rule_basis @ c, _SCALE_MARGIN) if not rule.holds(rule_basis @ c) else 1.0
    if t < 1.0:
        c = c * t
        W = basis_f @ c
        notes.append(f"W scaled by {t:.3f} to keep the band rule")
    helped = rule.excess_db(rule_basis @ c).max(axis=0) < -BAND_TOLERANCE_DB
    if not np.any(helped):
        notes.append(f"W reduces no band 20 Hz-2 kHz by more than {BAND_TOLERANCE_DB:g} dB: under the band rule a "
                     "causal filter of this reference leaves every band alone")
    return FeedforwardDesign(basis, c, f, W, notes)
