"""Fixed-point (Q15 in/out, Q31 states and coefficients) design of a section cascade.

Signals between sections are Q31 (int32, 1.0 = 2^31) in full-scale units. Each
section computes, with 64-bit accumulators and the "delta" feedback form
(design reference: poles near z = 1 need more coefficient precision than the
direct form's a1 ~ -2 leaves),

.. math::

    acc &= (\\sum_i B_i x_{n-i}) \\gg s_b + (C_1 y_{n-1} + C_2 y_{n-2}) \\gg s_c + e_{n-1} \\\\
    w &= acc \\gg r, \\quad e_n = acc - w 2^r \\\\
    y_n &= \\mathrm{sat}_{32}(w + 2 y_{n-1} - y_{n-2})

for a two-pole section (``+ y_{n-1}`` for one pole, nothing for none), which is
y = b.x - a1 y1 - a2 y2 with c1 = -a1 - 2, c2 = 1 - a2 (one pole: c1 = -a1 - 1).
B_i = round(b_i 2^(31 + n_b)) and C_i = round(c_i 2^(31 + n_c)) each carry their own
exponent so that small numerator gains and small delta coefficients keep about 30
significant bits; r = 31 + min(n_b, n_c) and s_b, s_c align the two sums.
``e`` is first-order error feedback (Higgins & Munson 1984; the floor error is
fed back, which shapes the round-off by 1 - z^-1); with the ``round`` quantiser e
is absent and w = (acc + 2^(r-1)) >> r.

Overflow cannot happen inside a section: sum|B_i| and sum|C_i| are kept at most
2^30 - 1, so each product sum is below 2^61 for any Q31 state (|x| <= 2^31) and
acc below 2^62 + 2^55 < 2^63 (0 <= e < 2^r <= 2^55). Only the section output is
saturated, never wrapped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import PrecisionError
from .sections import Cascade, Section

__all__ = [
    "QUANTISERS",
    "FixedDesign",
    "FixedSection",
    "delta_coefficients",
    "design_fixed",
    "polynomial_exponent",
]

QUANTISERS = ("efb", "round")
# Bound on sum|coefficient| in integer units: product sums with Q31 states stay < 2^61.
COEFFICIENT_SUM_LIMIT = 2**30 - 1
EXPONENT_MIN, EXPONENT_MAX = -24, 24


def delta_coefficients(section: Section) -> tuple[float, float]:
    """(c1, c2) of the delta feedback form: -a1 y1 - a2 y2 = base(y1, y2) + c1 y1 + c2 y2."""
    a1, a2 = section.a[1], section.a[2]
    if section.order == 2:
        return -a1 - 2.0, 1.0 - a2
    if section.order == 1:
        return -a1 - 1.0, 0.0
    return 0.0, 0.0


def _exponent(values, what: str) -> int:
    """Largest n in [EXPONENT_MIN, EXPONENT_MAX] with sum|round(v 2^(31+n))| within the limit."""
    for n in range(EXPONENT_MAX, EXPONENT_MIN - 1, -1):
        if sum(abs(round(v * 2.0 ** (31 + n))) for v in values) <= COEFFICIENT_SUM_LIMIT:
            return n
    raise PrecisionError(f"{what} coefficients too large for Q31 with shifts up to {-EXPONENT_MIN} bits")


@dataclass(frozen=True)
class FixedSection:
    """Integer coefficients and compile-time shifts of one section (see module docstring)."""

    order: int
    b: tuple[int, int, int]
    c: tuple[int, int]
    b_exponent: int
    c_exponent: int

    @property
    def shift(self) -> int:
        """r: right shift from the accumulator to Q31."""
        return 31 + min(self.b_exponent, self.c_exponent)

    @property
    def b_align(self) -> int:
        return self.b_exponent - min(self.b_exponent, self.c_exponent)

    @property
    def c_align(self) -> int:
        return self.c_exponent - min(self.b_exponent, self.c_exponent)

    def realised(self) -> Section:
        """The section these integers implement, as float64 b and a."""
        b = tuple(v / 2.0 ** (31 + self.b_exponent) for v in self.b)
        c1, c2 = (v / 2.0 ** (31 + self.c_exponent) for v in self.c)
        base1, base2 = {2: (2.0, -1.0), 1: (1.0, 0.0), 0: (0.0, 0.0)}[self.order]
        a = (1.0, -(c1 + base1), -(c2 + base2))
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
    b = [v * prescale for v in section.b]
    c = delta_coefficients(section)
    nb = _exponent(b, "numerator")
    nc = _exponent(c, "feedback") if any(c) else nb
    return FixedSection(
        order=section.order,
        b=tuple(round(v * 2.0 ** (31 + nb)) for v in b),
        c=tuple(round(v * 2.0 ** (31 + nc)) for v in c),
        b_exponent=nb,
        c_exponent=nc,
    )


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
