"""Fixed-point (Q15 in/out, Q31 states, 32-bit coefficients) design of a section cascade.

Signals between sections are Q31 (int32, 1.0 = 2^31) in full-scale units. Each
section is a direct form I with a 64-bit accumulator whose high word is the output,
shaped for the Cortex-M4's SMLAL (32 x 32 + 64 -> 64 in one instruction) and SSAT:

.. math::

    acc &= q_n + \\lfloor (A_1 y_{n-1} + A_2 y_{n-2}) / 2^d \\rfloor + \\sum_i B_i x_{n-i} \\\\
    y_n &= \\mathrm{sat}_{32-g}(\\lfloor acc / 2^{32} \\rfloor)\\, 2^g, \\quad e_n = acc \\bmod 2^{32}

with B_i = round(b_i 2^(32-g)) and A_i = round(-a_i 2^(32-g+d)) (CMSIS-DSP's sign
convention for the feedback), so acc / 2^32 = (b.x - a1 y1 - a2 y2) 2^-g. The output
is kept on a grid of 2^g Q31 LSBs: sat_{32-g} clamps to [-2^(31-g), 2^(31-g) - 1],
so y never leaves [-2^31, 2^31 - 2^g] (saturation, never wrap-around). ``q`` is the
quantiser: first-order error feedback q_n = e_{n-1} (Higgins & Munson 1984: the
floor residue fed back shapes the round-off by 1 - z^-1), or q = 2^31, rounding to
nearest. On the board both the high word and the residue (the low word) are free.

The residue e lies in [0, 2^32) (one output step), mean half a step; at rest it holds that mean,
:data:`EFB_RESIDUE_AT_REST` = 2^31. Started at 0, the first sample's round-off carries a step of half
an output step that the shaping 1 - z^-1 turns into an impulse, and 1 / A_k rings it unshaped:
for poles near z = 1 a transient whose energy is the unshaped noise gain's. Measured on the seed
pair's designed W (89 states, 45 sections, poles at 0.9986-0.9992 from 4 to 34 Hz, +20.6 dB at 3 Hz):
the Q15 error over a 0.4 s sweep was 718 times the predicted steady round-off (24.2 dB SNR against
52.3 predicted), 145 times over 2 s (the energy fixed, the power falling as 1 / length); started
at the mean, 1.0-1.4 times (51.8 dB).

``g`` (the guard exponent) is the smallest that keeps every coefficient in int32 and
the accumulator in int64: with |x|, |y| <= 2^31, |acc| <= (sum|A| 2^-d + sum|B|) 2^31
+ 2^32 < 2^63 when the coefficient sums stay within :data:`COEFFICIENT_SUM_LIMIT`.
A feedback polynomial near (1 - z^-1)^2 has |a1| + |a2| close to 3, so g is 2-3
and the feedback coefficients keep 29-31 fractional bits (d = 0). When the numerator
pushes g beyond 3 (a section with a big gain, e.g. a zero near z = 1 against a pole
near z = 1), the feedback gets its own d extra fractional bits and its product sum is
shifted down by d (one 64-bit shift) instead of losing them.

Below the steps of firmware generation: a design module (it imports the sections and
the errors) that the generic target's Q15 variant (:mod:`codegen.targets`) runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import PrecisionError
from .sections import Cascade, Section

__all__ = [
    "COEFFICIENT_SUM_LIMIT",
    "EFB_RESIDUE_AT_REST",
    "QUANTISERS",
    "FixedDesign",
    "FixedSection",
    "delta_coefficients",
    "design_fixed",
    "polynomial_exponent",
]

QUANTISERS = ("efb", "round")
# Bound on sum|A| 2^-d + sum|B| in integer units: (2^32 - 4) 2^31 + 2^32 < 2^63.
COEFFICIENT_SUM_LIMIT = 2**32 - 4
INT32_LIMIT = 2**31 - 1
GUARD_MAX = 30
# The error-feedback residue at rest: its mean, half an output step (module docstring).
EFB_RESIDUE_AT_REST = 1 << 31
FEEDBACK_GUARD = 3


def delta_coefficients(section: Section) -> tuple[float, float]:
    """(c1, c2) of the delta feedback form: -a1 y1 - a2 y2 = base(y1, y2) + c1 y1 + c2 y2 (the float32 variant)."""
    a1, a2 = section.a[1], section.a[2]
    if section.order == 2:
        return -a1 - 2.0, 1.0 - a2
    if section.order == 1:
        return -a1 - 1.0, 0.0
    return 0.0, 0.0


def _integers(values, exponent: int) -> tuple[int, ...]:
    return tuple(round(v * 2.0**exponent) for v in values)


def _fits(b, a, guard: int, d: int) -> bool:
    big_b, big_a = _integers(b, 32 - guard), _integers(a, 32 - guard + d)
    if max(abs(v) for v in (*big_b, *big_a)) > INT32_LIMIT:
        return False
    return sum(abs(v) for v in big_a) / 2.0**d + sum(abs(v) for v in big_b) <= COEFFICIENT_SUM_LIMIT


@dataclass(frozen=True)
class FixedSection:
    """Integer coefficients, guard exponent g and feedback shift d of one section (module docstring)."""

    order: int
    b: tuple[int, int, int]
    a: tuple[int, int]
    guard: int
    feedback_shift: int

    @property
    def b_exponent(self) -> int:
        """Fractional bits of B: B = b 2^b_exponent."""
        return 32 - self.guard

    @property
    def a_exponent(self) -> int:
        """Fractional bits of A: A = -a 2^a_exponent."""
        return 32 - self.guard + self.feedback_shift

    def realised(self) -> Section:
        """The section these integers implement, as float64 b and a."""
        b = tuple(v / 2.0**self.b_exponent for v in self.b)
        a = (1.0, *(-v / 2.0**self.a_exponent for v in self.a))
        return Section(b=b, a=a, poles=tuple(np.roots(a[: self.order + 1]).astype(complex)), zeros=())


@dataclass(frozen=True)
class FixedDesign:
    """The complete fixed-point algorithm: delay line, input polynomial, sections.

    ``polynomial`` holds P_k = round(a_k 2^(31 - polynomial_exponent)) for
    v = a_1 u + a_2 u^2 + ...; the cascade input is then x = v 2^-polynomial_exponent
    in Q31 and the first section's numerator carries the factor 2^polynomial_exponent.
    """

    sections: tuple[FixedSection, ...]
    quantiser: str
    delay: int
    polynomial: tuple[int, ...] | None
    polynomial_exponent: int


def polynomial_exponent(coefficients) -> int:
    """Smallest e >= 0 with sum|a_k| <= 2^e (1 - 2^-30): Horner on |u| <= 1 then stays in Q31."""
    total = float(np.sum(np.abs(coefficients)))
    e = 0
    while total > 2.0**e * (1 - 2.0**-30):
        e += 1
        if e > 30:
            raise PrecisionError("input polynomial coefficients are too large for Q31")
    return e


def _quantise_section(section: Section, prescale: float) -> FixedSection:
    """Smallest guard g that fits (module docstring), then the most feedback bits d that still fit."""
    b = [v * prescale for v in section.b]
    a = [-section.a[1], -section.a[2]]
    for guard in range(0, GUARD_MAX + 1):
        if _fits(b, a, guard, 0):
            break
    else:
        raise PrecisionError(f"section coefficients too large for 32-bit integers with {GUARD_MAX} guard bits")
    d = 0
    # A stable feedback (|a1| < 2, |a2| < 1) fits with FEEDBACK_GUARD alone; only a numerator that
    # pushes g beyond it takes bits from the feedback worth an extra shift to give back.
    while guard > FEEDBACK_GUARD and section.order and d < 31 and _fits(b, a, guard, d + 1):
        d += 1
    return FixedSection(order=section.order, b=_integers(b, 32 - guard), a=_integers(a, 32 - guard + d),
                        guard=guard, feedback_shift=d)


def design_fixed(cascade: Cascade, delay: int, input_polynomial=None, quantiser: str = "efb") -> FixedDesign:
    """Quantise a scaled cascade into the fixed-point algorithm of the module docstring."""
    if quantiser not in QUANTISERS:
        raise PrecisionError(f"quantiser must be one of {', '.join(QUANTISERS)}; found {quantiser!r}")
    poly, exponent = None, 0
    if input_polynomial is not None:
        exponent = polynomial_exponent(input_polynomial)
        poly = tuple(round(a * 2.0 ** (31 - exponent)) for a in input_polynomial)
    sections = tuple(
        _quantise_section(s, 2.0**exponent if k == 0 else 1.0) for k, s in enumerate(cascade.sections)
    )
    return FixedDesign(sections=sections, quantiser=quantiser, delay=int(delay), polynomial=poly,
                       polynomial_exponent=exponent)
