"""Float32 design of a section cascade: two-pole sections as balanced state spaces, the rest around z = 1.

Every node of the cascade (its input, each section's output) carries a sample v and its
first difference d = v[n] - v[n-1]. Each section computes, in float32 and in exactly this
order (the generated C, :func:`codegen.reference.float32_reference` and the control path's
twin share it; terms whose coefficient is exactly zero are left out of all three), from its
input node (v, d) its output node (w, e), ``1`` marking the previous sample:

    two poles:  w = (D v0 + c1 s1) + c2 s2;  s_i = s_i + ((n_i1 s1 + n_i2 s2) + g_i v0)
                (i = 1, 2, both from the old s);  e = w - w1
    one pole:   e = f + k1 w1;  w = w1 + e
    no pole:    w = f;  e = w - w1

with the numerator f = (b0 (d0 - d1) + m1 v1) + m2 d1 (three taps; two: b0 d0 + m1 v1; one: b0 v0).

A two-pole section b(z) / a(z) is the balanced realisation (A, g, c, D) of the section itself
(Moore 1981, :func:`sysid.core.lti.minimal_balanced_realisation`, from its normal form
[[sigma, -omega], [omega, sigma]] or, for real poles, a chain) with N = A - I stored: the delta
operator's state matrix (Middleton & Goodwin, "Improved finite word length characteristics in
digital control using delta operators", IEEE TAC 31(11), 1986), whose entries are of the size
of the poles' distance from z = 1 and keep it to float32's relative precision. A direct form's
rounding reaches the output through 1 / a(z), whose noise gain is about 1 / (4 r (r^2 + theta^2))
for poles at distance r from the unit circle and angle theta (1e11 at 1e-4: float32 rounding
some 46 dB below the signal at best), and its b0, b1, b2 of a zero pair 1e-4 from the unit
circle near 20 Hz sum to 1e-5 of b0, so their notch moves (coefficient SNR 23-27 dB on the
designed controllers); the balanced states' rounding reaches the output with a gain of order
1 / r (Mullis & Roberts, "Synthesis of minimum roundoff noise fixed point digital filters",
IEEE TCAS 23(9), 1976), and the section's response is held to 83-133 dB there.

The other sections' numerators are expanded around z = 1 (delta = 1 - z^-1):
b(z) = b0 delta^2 + m1 z^-1 + m2 z^-1 delta with m1 = b(1) = b0 + b1 + b2 and m2 = b0 - b2 (two
taps: m1 = b0 + b1), so zeros near z = 1 are held by small numbers; one pole is stored as
k1 = -(1 + a1) (its noise gain 1 / (1 - p^2) needs no more).

Below the steps of firmware generation: a design module (it imports the sections and
``sysid.core.lti``) that the generic target's float variant runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sysid.core.lti import minimal_balanced_realisation

from .sections import Cascade, Section

__all__ = ["FloatDesign", "FloatSection", "RealisedSection", "delta_form", "design_float32", "state_realisation"]


@dataclass(frozen=True)
class RealisedSection:
    """A section as float64 polynomials in z^-1 (numerator of any length), for its frequency response."""

    b: tuple[float, ...]
    a: tuple[float, float, float]
    order: int

    def response(self, w: np.ndarray) -> np.ndarray:
        zi = np.exp(-1j * np.asarray(w))
        return np.polyval(self.b[::-1], zi) / np.polyval(self.a[::-1], zi)


@dataclass(frozen=True)
class FloatSection:
    """float32 coefficients of one section (module docstring).

    A two-pole section holds its balanced state space: ``b`` = (D, 0, 0) (``taps`` 1),
    ``n`` = (n11, n12, n21, n22) = A - I, ``g`` = (g1, g2) = B and ``c`` = (c1, c2) = C. Otherwise
    ``taps`` is the numerator's length (0-3) and ``b`` its delta form (b0, m1, m2) (two taps:
    m1 = b0 + b1, m2 = 0), a one-pole section has ``c`` = (k1, 0) with k1 = -(1 + a1) and empty
    ``n``, ``g``.
    """

    order: int
    taps: int
    b: tuple[float, float, float]
    c: tuple[float, float]
    n: tuple[float, ...] = ()
    g: tuple[float, ...] = ()

    def realised(self) -> RealisedSection:
        """The section these float32 numbers implement, as float64 polynomials (exact but for the last bits)."""
        b0, m1, m2 = (float(v) for v in self.b)
        b = {3: (b0, m1 + m2 - 2.0 * b0, b0 - m2), 2: (b0, m1 - b0, 0.0), 1: (b0, 0.0, 0.0), 0: (0.0, 0.0, 0.0)}[self.taps]
        if self.order == 2:
            A = np.eye(2) + np.array(self.n, float).reshape(2, 2)
            g, c = np.array(self.g, float), np.array(self.c, float)
            a = (1.0, -float(np.trace(A)), float(np.linalg.det(A)))
            # D + c (zI - A)^-1 g = (D (z^2 + a1 z + a2) + (c.g) z + c adj(-A) g) / (z^2 + a1 z + a2).
            adjugate = np.array([[-A[1, 1], A[0, 1]], [A[1, 0], -A[0, 0]]])
            b = (b0, b0 * a[1] + float(c @ g), b0 * a[2] + float(c @ adjugate @ g))
            return RealisedSection(b=b, a=a, order=2)
        k1 = float(self.c[0])
        a = (1.0, -1.0 - k1, 0.0) if self.order == 1 else (1.0, 0.0, 0.0)
        return RealisedSection(b=b, a=a, order=self.order)


@dataclass(frozen=True)
class FloatDesign:
    """Delay line, float32 input polynomial (a1, a2, ...) and sections."""

    sections: tuple[FloatSection, ...]
    delay: int
    polynomial: tuple[float, ...] | None


def _f32(value: float) -> float:
    return float(np.float32(value))


def delta_form(section: Section) -> tuple[int, tuple[float, float, float], tuple[float, float]]:
    """(taps, (b0, m1, m2), (k1, k2)) of a section in float64: the numerator and the feedback
    -a(1), a2 - 1 expanded around z = 1 (module docstring)."""
    b0, b1, b2 = (float(v) for v in section.b)
    a1, a2 = float(section.a[1]), float(section.a[2])
    taps = 3 if b2 != 0.0 else 2 if b1 != 0.0 else 1 if b0 != 0.0 else 0
    numerator = {3: (b0, b0 + b1 + b2, b0 - b2), 2: (b0, b0 + b1, 0.0), 1: (b0, 0.0, 0.0), 0: (0.0, 0.0, 0.0)}[taps]
    feedback = {2: (-(1.0 + a1 + a2), a2 - 1.0), 1: (-(1.0 + a1), 0.0), 0: (0.0, 0.0)}[section.order]
    return taps, numerator, feedback


def state_realisation(section: Section) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(N = A - I, g, c, D) in float64 of the balanced realisation of a two-pole section's b(z) / a(z)."""
    b0, b1, b2 = (float(v) for v in section.b)
    a1, a2 = float(section.a[1]), float(section.a[2])
    poles = np.asarray(section.poles, complex)
    # b / a = b0 + (r1 z + r0) / (z^2 + a1 z + a2).
    r1, r0 = b1 - b0 * a1, b2 - b0 * a2
    if abs(poles[0].imag) > 0.0:
        sigma, omega = poles[0].real, abs(poles[0].imag)
        # Normal form: (zI - A)^-1 [1, 0]^T = [z - sigma, omega]^T / ((z - sigma)^2 + omega^2).
        A = np.array([[sigma, -omega], [omega, sigma]])
        C = np.array([[r1, (r0 + r1 * sigma) / omega]])
    else:
        p1, p2 = sorted(float(p.real) for p in poles)
        # Chain: (zI - A)^-1 [1, 0]^T = [1 / (z - p1), 1 / ((z - p1)(z - p2))]^T (coincident poles too).
        A = np.array([[p1, 0.0], [1.0, p2]])
        C = np.array([[r1, r0 + r1 * p2]])
    B = np.array([[1.0], [0.0]])
    balanced = minimal_balanced_realisation(A, B, C, b0)
    if balanced.A.shape[0] == 2:
        A, B, C = balanced.A, balanced.B, balanced.C
    return A - np.eye(2), B.ravel(), C.ravel(), b0


def design_float32(cascade: Cascade, delay: int, input_polynomial=None) -> FloatDesign:
    """Round the cascade's coefficients in the forms of the module docstring to float32 (kept as exact floats)."""
    sections = []
    for s in cascade.sections:
        taps, numerator, feedback = delta_form(s)
        b = tuple(_f32(v) for v in numerator)
        if s.order == 2:
            N, g, c, direct = state_realisation(s)
            sections.append(FloatSection(order=2, taps=1, b=(_f32(direct), 0.0, 0.0), c=tuple(_f32(v) for v in c),
                                         n=tuple(_f32(v) for v in N.ravel()), g=tuple(_f32(v) for v in g)))
        else:
            sections.append(FloatSection(order=s.order, taps=taps, b=b, c=tuple(_f32(v) for v in feedback)))
    poly = None if input_polynomial is None else tuple(_f32(a) for a in input_polynomial)
    return FloatDesign(sections=tuple(sections), delay=int(delay), polynomial=poly)
