"""The FB model's minimum-phase (outer) factor, whose inverse is the fixed part of the feedback filter.

With the FB model S_model(z) = z^-d S_core(z), S_core = K prod_i (z - zeta_i) / prod_i (z - p_i)
(n poles, n - r finite zeros, r the relative degree), and the latency L, the loop's path is

.. math::
    G = z^{-L} S_{model} = z^{-(L + d + r)} \\, B(z) \\, S_o(z), \\qquad
    S_o(z) = K' z^r \\frac{\\prod_i (z - w_i)}{\\prod_i (z - p_i)},

with w_i = zeta_i inside the unit circle and 1 / conj(zeta_i) outside it, B the all-pass
(Blaschke) product of the zeros outside, |B| = 1 on the circle, and K' > 0 so that
|S_o| = |S_core| there (the inner-outer factorisation: Morari & Zafiriou, "Robust Process
Control", Prentice Hall 1989, sec. 4.1, eq. 4.1-4, for the factorisation of internal model
control; Francis, "A Course in H-infinity Control Theory", Springer 1987, ch. 4).

Writing the feedback filter Q = S_o^-1 X makes G Q = z^{-(L + d + r)} B X: the loop is the free
part X through a pure dead time and an all-pass, so the responses a design bounds are all of
X's size and a basis for X is equally well conditioned at every frequency (``anc.feedback_bound``).
A zero within ``CIRCLE_MARGIN`` of the unit circle (a path's DC zero, a sampling zero at z = -1)
cannot be inverted stably: it is taken at radius 1 - ``CIRCLE_MARGIN`` instead, so S_o is
exactly outer only away from it. That changes the parametrisation, never a result: every
response is evaluated with the exact G.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sysid.core.model import Model
from sysid.core.response import frequency_response
from sysid.core.sections import pair_sections, unit_section
from sysid.core.structures import series, tf_to_statespace

__all__ = ["OuterFactor", "outer_factor", "CIRCLE_MARGIN"]

CIRCLE_MARGIN = 1e-3


@dataclass(frozen=True)
class OuterFactor:
    """S_o of a model (module docstring): its poles (the model's), zeros ``inside`` (w_i), gain K',
    the relative degree r, the model's delay d and its zeros outside the unit circle."""

    fs: float
    poles: np.ndarray
    inside: np.ndarray
    gain: float
    relative_degree: int
    delay: int
    outside: np.ndarray

    def _unit(self, frequencies_hz) -> np.ndarray:
        z = np.exp(2j * np.pi * np.asarray(frequencies_hz, dtype=float) / self.fs)
        numerator = np.prod(z[:, None] - self.inside[None, :], axis=1)
        denominator = np.prod(z[:, None] - self.poles[None, :], axis=1)
        return z**self.relative_degree * numerator / denominator

    def response(self, frequencies_hz) -> np.ndarray:
        """S_o at frequencies in Hz."""
        return self.gain * self._unit(frequencies_hz)

    def inverse_response(self, frequencies_hz) -> np.ndarray:
        """S_o^-1 at frequencies in Hz."""
        return 1.0 / self.response(frequencies_hz)

    @property
    def dead_time(self) -> int:
        """d + r: the samples of pure delay in S_model (to which the loop adds the latency)."""
        return self.delay + self.relative_degree

    def nonminimum_phase_hz(self) -> np.ndarray:
        """The equivalent frequency |ln zeta| fs / 2 pi (Hz) of each zero outside the unit circle (that of
        the continuous-time zero s = fs ln zeta: a real zeta = 1.0089 at 44.1 kHz is a zero at 62 Hz)."""
        return np.abs(np.log(self.outside.astype(complex))) * self.fs / (2.0 * np.pi)

    def inverse_statespace(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C, D) of S_o^-1 = z^-r prod (z - p_i) / (K' prod (z - w_i)): a cascade of sections of at
        most two poles (``sysid.core.sections``), never a high-order polynomial."""
        poles = np.concatenate((self.inside, np.zeros(self.relative_degree)))
        sections = [unit_section(p, z) for p, z in pair_sections(poles, self.poles)]
        system = None
        for section in sections:
            block = tf_to_statespace(np.array(section.b), np.array(section.a))
            system = block if system is None else series(system, block)
        A, B, C, D = system
        return A, B, C / self.gain, D / self.gain


def outer_factor(model: Model) -> OuterFactor:
    """The outer factor S_o of the model's LTI core (module docstring)."""
    fs = model.fs
    poles = model.poles()
    zeros = model.zeros()
    outside = zeros[np.abs(zeros) > 1.0]
    w = np.where(np.abs(zeros) > 1.0, 1.0 / np.conj(zeros), zeros)
    radius = np.abs(w)
    w = np.where(radius > 1.0 - CIRCLE_MARGIN, w / np.maximum(radius, 1e-300) * (1.0 - CIRCLE_MARGIN), w)
    relative_degree = int(poles.size - zeros.size)
    unit = OuterFactor(fs, poles, w, 1.0, relative_degree, model.delay, outside)
    # K' from the magnitudes on a log grid over the audible range (exact wherever no zero was moved).
    f = np.geomspace(20.0, 0.45 * fs, 400)
    core = np.abs(frequency_response(model.A, model.B, model.C, model.D, np.exp(2j * np.pi * f / fs)))
    gain = float(np.exp(np.median(np.log(np.maximum(core, 1e-300)) - np.log(np.abs(unit._unit(f))))))
    return OuterFactor(fs, poles, w, gain, relative_degree, model.delay, outside)
