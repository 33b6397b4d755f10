"""Float32 design of a section cascade: the same delta feedback form as the fixed point.

Each section computes, in float32 and in exactly this order (the generated C and
:func:`codegen.reference.float32_reference` share it; terms whose coefficient is
exactly zero are left out of both),

    f = ((b0 x0 + b1 x1) + b2 x2);  t = (f + c1 y1) + c2 y2;  y = t + (2 y1 - y2)

(``+ y1`` for a one-pole section). Storing c1 = -a1 - 2 and c2 = 1 - a2 instead of
a1 ~ -2 keeps float32's relative precision on the small distance of the poles from
z = 1; the design reference measured 45-59 dB for plain float32 DF2T on these poles,
all of it from coefficient rounding.

Below the steps of firmware generation: a design module (it imports the sections and
:mod:`codegen.fixedpoint`'s delta coefficients) that the generic target's float variant runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fixedpoint import delta_coefficients
from .sections import Cascade, Section

__all__ = ["FloatDesign", "FloatSection", "design_float32"]


@dataclass(frozen=True)
class FloatSection:
    """float32 coefficients (b0, b1, b2) and (c1, c2) of one section."""

    order: int
    b: tuple[float, float, float]
    c: tuple[float, float]

    def realised(self) -> Section:
        c1, c2 = (float(v) for v in self.c)
        base1, base2 = {2: (2.0, -1.0), 1: (1.0, 0.0), 0: (0.0, 0.0)}[self.order]
        a = (1.0, -(c1 + base1), -(c2 + base2))
        return Section(b=tuple(float(v) for v in self.b), a=a,
                       poles=tuple(np.roots(a[: self.order + 1]).astype(complex)), zeros=())


@dataclass(frozen=True)
class FloatDesign:
    """Delay line, float32 input polynomial (a1, a2, ...) and sections."""

    sections: tuple[FloatSection, ...]
    delay: int
    polynomial: tuple[float, ...] | None


def _f32(value: float) -> float:
    return float(np.float32(value))


def design_float32(cascade: Cascade, delay: int, input_polynomial=None) -> FloatDesign:
    """Round the cascade's coefficients to float32 (values kept as exact Python floats)."""
    sections = tuple(
        FloatSection(order=s.order, b=tuple(_f32(v) for v in s.b), c=tuple(_f32(v) for v in delta_coefficients(s)))
        for s in cascade.sections
    )
    poly = None if input_polynomial is None else tuple(_f32(a) for a in input_polynomial)
    return FloatDesign(sections=sections, delay=int(delay), polynomial=poly)
