"""Float32 design of a section cascade: sections in the delta operator's difference form.

Every node of the cascade (its input, each section's output) carries a sample v and its
first difference d = v[n] - v[n-1]. Each section computes, in float32 and in exactly this
order (the generated C, :func:`codegen.reference.float32_reference` and the control path's
twin share it; terms whose coefficient is exactly zero are left out of all three),

    f = (b0 (d0 - d1) + m1 v1) + m2 d1                    (numerator, three taps)
    t = (f + k1 w1) + k2 e1;  e = e1 + t;  w = w1 + e      (two poles)

with (v, d) the section's input node and (w, e) its output node, ``1`` marking the previous
sample; a one-pole section has e = f + k1 w1, w = w1 + e, a section without poles w = f,
e = w - w1, and a two-tap numerator f = b0 d0 + m1 v1. The stored coefficients are the
section's polynomials expanded around z = 1 (the delta operator delta = 1 - z^-1;
Middleton & Goodwin, "Improved finite word length characteristics in digital control
using delta operators", IEEE TAC 31(11), 1986):

    b(z) = b0 delta^2 + m1 z^-1 + m2 z^-1 delta,   m1 = b(1) = b0 + b1 + b2,  m2 = b0 - b2
    a(z) = delta^2 - k1 z^-1 - k2 z^-1 delta,      k1 = -a(1) = -(1 + a1 + a2),  k2 = a2 - 1

For poles and zeros near z = 1 these are the small numbers a float32 keeps to its relative
precision: a1 ~ -2 stored plainly loses the distance of the poles from z = 1 (1e-4 on the
designed controllers: 24 bits of 2 leave 1e-7 absolute, 1e-3 of it), and b0, b1, b2 of a
zero pair 1e-4 from the unit circle near 20 Hz sum to 1e-5 of b0, so plainly stored their
notch moved (coefficient SNR 23-27 dB against 85-107 dB in this form, the designed
controllers of the seed pair). The states are differences too: the rounding of w = w1 + e
reaches the output through (1 - a2 z^-1) / a(z), not 1 / a(z) as a direct form's output
rounding does, and that of e is relative to the difference's own, smaller, magnitude
(W of the seed pair, poles 2.4e-4 from the unit circle: predicted round-off SNR 22 dB in
the direct form's delta-coefficient variant, see :mod:`codegen.noise` for this one).

Below the steps of firmware generation: a design module (it imports the sections only)
that the generic target's float variant runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sections import Cascade, Section

__all__ = ["FloatDesign", "FloatSection", "delta_form", "design_float32"]


@dataclass(frozen=True)
class FloatSection:
    """float32 numerator (b0, m1, m2) and feedback (k1, k2) of one section in the delta form.

    ``taps`` is the numerator's length (0-3): three taps use (b0, m1, m2), two use
    (b0, m1) with m1 = b0 + b1, one uses b0 alone (f = b0 v0).
    """

    order: int
    taps: int
    b: tuple[float, float, float]
    c: tuple[float, float]

    def realised(self) -> Section:
        """The section these float32 numbers implement, as float64 b and a (exact in float64)."""
        b0, m1, m2 = (float(v) for v in self.b)
        k1, k2 = (float(v) for v in self.c)
        b = {3: (b0, m1 + m2 - 2.0 * b0, b0 - m2), 2: (b0, m1 - b0, 0.0), 1: (b0, 0.0, 0.0), 0: (0.0, 0.0, 0.0)}[self.taps]
        a = {2: (1.0, -2.0 - k1 - k2, 1.0 + k2), 1: (1.0, -1.0 - k1, 0.0), 0: (1.0, 0.0, 0.0)}[self.order]
        return Section(b=b, a=a, poles=tuple(np.roots(a[: self.order + 1]).astype(complex)), zeros=())


@dataclass(frozen=True)
class FloatDesign:
    """Delay line, float32 input polynomial (a1, a2, ...) and sections."""

    sections: tuple[FloatSection, ...]
    delay: int
    polynomial: tuple[float, ...] | None


def _f32(value: float) -> float:
    return float(np.float32(value))


def delta_form(section: Section) -> tuple[int, tuple[float, float, float], tuple[float, float]]:
    """(taps, (b0, m1, m2), (k1, k2)) of a section in float64 (module docstring)."""
    b0, b1, b2 = (float(v) for v in section.b)
    a1, a2 = float(section.a[1]), float(section.a[2])
    taps = 3 if b2 != 0.0 else 2 if b1 != 0.0 else 1 if b0 != 0.0 else 0
    numerator = {3: (b0, b0 + b1 + b2, b0 - b2), 2: (b0, b0 + b1, 0.0), 1: (b0, 0.0, 0.0), 0: (0.0, 0.0, 0.0)}[taps]
    feedback = {2: (-(1.0 + a1 + a2), a2 - 1.0), 1: (-(1.0 + a1), 0.0), 0: (0.0, 0.0)}[section.order]
    return taps, numerator, feedback


def design_float32(cascade: Cascade, delay: int, input_polynomial=None) -> FloatDesign:
    """Round the cascade's delta-form coefficients to float32 (values kept as exact Python floats)."""
    sections = []
    for s in cascade.sections:
        taps, numerator, feedback = delta_form(s)
        sections.append(FloatSection(order=s.order, taps=taps, b=tuple(_f32(v) for v in numerator),
                                     c=tuple(_f32(v) for v in feedback)))
    poly = None if input_polynomial is None else tuple(_f32(a) for a in input_polynomial)
    return FloatDesign(sections=tuple(sections), delay=int(delay), polynomial=poly)
