"""Python references of the generated filters: bit-exact fixed point, float32, float64.

:func:`fixed_reference` is the specification of the generated Q15 code: integer
for integer the same operations (Python integers, :func:`fixed_section` per section
with its state returned so blocks can be chained), so the C output must agree to 0 LSB.
:func:`float32_reference` performs the float32 operations of the generated float
code in the same order. :func:`float64_reference` is the realised model in double
precision, the yardstick of the signal-to-noise ratios.

The cascade is processed section after section over the whole signal: each
section's output depends only on its input sequence, so this equals the C code's
order (the Q15 code runs section after section over blocks of up to
``NAME_Q15_CHUNK`` samples, the float code sample after sample).

Below the steps of firmware generation: the targets' variants name these references and
verification runs them; it imports the designs and the realisation.
"""

from __future__ import annotations

import numpy as np

from sysid.core import lti

from .fixedpoint import EFB_RESIDUE_AT_REST, FixedDesign, FixedSection
from .float32 import FloatDesign
from .realise import Realisation

__all__ = ["FixedFilter", "delay_signal", "fixed_input", "fixed_reference", "fixed_section", "q31_to_q15_output", "float32_input", "float32_reference", "float64_reference", "from_q15", "to_q15"]

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1


def to_q15(x: np.ndarray) -> np.ndarray:
    """Full-scale floats to 16-bit PCM: round to nearest, saturate to [-32768, 32767]."""
    return np.clip(np.round(np.asarray(x, float) * 32768.0), -32768, 32767).astype(np.int16)


def from_q15(x: np.ndarray) -> np.ndarray:
    """16-bit PCM to full-scale floats (x / 32768)."""
    return np.asarray(x, np.int16).astype(float) / 32768.0


def delay_signal(x: np.ndarray, delay: int) -> np.ndarray:
    """x delayed by ``delay`` samples from rest (the circular buffer starts zeroed)."""
    if delay == 0:
        return x
    out = np.zeros_like(x)
    out[delay:] = x[: max(x.size - delay, 0)]
    return out


def _history(x: np.ndarray, lag: int) -> np.ndarray:
    out = np.zeros_like(x)
    out[lag:] = x[: x.size - lag]
    return out


def fixed_section(section: FixedSection, x: np.ndarray, quantiser: str, state=None) -> tuple[np.ndarray, tuple]:
    """One section of the Q15 filter (:mod:`codegen.fixedpoint`) on Q31 input x (int64 array).

    ``state`` is (x1, x2, y1, y2, e) from a previous call (None: from rest, the residue e at
    its mean ``EFB_RESIDUE_AT_REST``); returns the Q31 output and the state after the last sample, so
    blocks can be chained.
    """
    x1, x2, y1, y2, e = state or (0, 0, 0, 0, EFB_RESIDUE_AT_REST)
    b0, b1, b2 = section.b
    a1, a2 = section.a
    d, guard = section.feedback_shift, section.guard
    top, bottom, unit = (1 << (31 - guard)) - 1, -(1 << (31 - guard)), 1 << guard
    efb = quantiser == "efb"
    y = np.empty(x.shape, np.int64)
    for n, x0 in enumerate(x.tolist()):
        acc = ((a1 * y1 + a2 * y2) >> d) + (e if efb else 1 << 31) + b0 * x0 + b1 * x1 + b2 * x2
        if efb:
            e = acc & 0xFFFFFFFF
        high = acc >> 32
        y0 = (top if high > top else max(high, bottom)) * unit
        x2, x1, y2, y1 = x1, x0, y1, y0
        y[n] = y0
    return y, (x1, x2, y1, y2, e)


def _polynomial_q31(design: FixedDesign, u: np.ndarray) -> np.ndarray:
    """Q31 cascade input (int64) for delayed Q15 input u: u 2^16, or the input polynomial in Q31."""
    if design.polynomial is None:
        return u * 65536
    # Horner in Q31 with floor shifts: acc = P_k + (acc u) >> 15, then x = (acc u) >> 15.
    acc = np.full(u.shape, design.polynomial[-1], dtype=np.int64)
    for p in design.polynomial[-2::-1]:
        acc = p + ((acc * u) >> 15)
    return (acc * u) >> 15


def fixed_input(design: FixedDesign, u: np.ndarray) -> np.ndarray:
    """Q31 cascade input (int64 array) of the Q15 filter for Q15 input u from rest: delay, then polynomial or u 2^16."""
    return _polynomial_q31(design, delay_signal(np.asarray(u, dtype=np.int16).astype(np.int64), design.delay))


def q31_to_q15_output(x: np.ndarray) -> np.ndarray:
    """Q31 -> Q15 output word: round to nearest ((x + 2^15) >> 16), saturate."""
    return np.clip((np.asarray(x, np.int64) + 32768) >> 16, -32768, 32767).astype(np.int16)


def fixed_reference(design: FixedDesign, u: np.ndarray) -> np.ndarray:
    """Bit-exact output (int16) of the generated Q15 filter for Q15 input u, from rest."""
    x = fixed_input(design, u)
    for section in design.sections:
        x, _ = fixed_section(section, x, design.quantiser)
    return q31_to_q15_output(x)


class FixedFilter:
    """The generated Q15 filter with its state carried between blocks, as the C's ``process()``.

    For loops that need each output before the next input (closed-loop simulation):
    ``process`` on blocks of any length, including 1, equals :func:`fixed_reference`
    on the concatenated input.
    """

    def __init__(self, design: FixedDesign):
        self.design = design
        self.reset()

    def reset(self) -> None:
        """Back to rest (the C's ``reset()``)."""
        self._line = np.zeros(self.design.delay, np.int64)
        self._states = [None] * len(self.design.sections)

    def process(self, u) -> np.ndarray:
        """Q15 samples (int16) in, Q15 samples out."""
        u = np.asarray(u, dtype=np.int16).astype(np.int64).reshape(-1)
        joined = np.concatenate((self._line, u))
        delayed, self._line = joined[: u.size], joined[u.size:]
        x = _polynomial_q31(self.design, delayed)
        for k, section in enumerate(self.design.sections):
            x, self._states[k] = fixed_section(section, x, self.design.quantiser, self._states[k])
        return q31_to_q15_output(x)


def float32_input(design: FloatDesign, u: np.ndarray) -> np.ndarray:
    """float32 cascade input for float32 input u from rest: delay, then the input polynomial by Horner."""
    f32 = np.float32
    u = delay_signal(np.asarray(u, dtype=f32), design.delay)
    if design.polynomial is None:
        return u
    # Horner: v = a_K; v = a_k + v u; ...; x = v u (all float32).
    acc = np.full(u.shape, design.polynomial[-1], dtype=f32)
    for a in design.polynomial[-2::-1]:
        acc = f32(a) + acc * u
    return acc * u


def _float32_coefficients(design: FloatDesign) -> dict:
    """The sections' float32 coefficients as arrays over the sections, zeros where a form has none."""
    f32 = np.float32
    sections = design.sections
    column = lambda values: np.array(values, dtype=f32)  # noqa: E731
    return {
        "taps": np.array([s.taps for s in sections]), "order": np.array([s.order for s in sections]),
        "b0": column([s.b[0] for s in sections]), "m1": column([s.b[1] for s in sections]),
        "m2": column([s.b[2] for s in sections]),
        "c1": column([s.c[0] for s in sections]), "c2": column([s.c[1] if s.order == 2 else 0.0 for s in sections]),
        "n": [column([s.n[i] if s.order == 2 else 0.0 for s in sections]) for i in range(4)],
        "g": [column([s.g[i] if s.order == 2 else 0.0 for s in sections]) for i in range(2)],
    }


def float32_reference(design: FloatDesign, u: np.ndarray) -> np.ndarray:
    """Output (float32) of the generated float filter for float32 input u, from rest.

    The sections run skewed in time (section k on sample t - k at step t), so every step is one
    float32 operation per section over all sections at once; each element is the same IEEE float32
    operation as the C's. A term whose coefficient is zero, which the C leaves out, adds an exact
    zero here.
    """
    f32 = np.float32
    x = float32_input(design, u)
    count = len(design.sections)
    if count == 0 or x.size == 0:
        return x
    k = _float32_coefficients(design)
    zero = np.zeros(count, f32)
    v1, d1, w1, e1, s1, s2 = (zero.copy() for _ in range(6))
    three, two, one = k["taps"] == 3, k["taps"] == 2, k["taps"] == 1
    pole2, pole1 = k["order"] == 2, k["order"] == 1
    steps = x.size + count - 1
    source = np.concatenate((x, np.zeros(count - 1, f32)))
    source_d = (source - np.concatenate(([f32(0.0)], source[:-1]))).astype(f32)
    out = np.empty(x.size, f32)
    for t in range(steps):
        v = np.concatenate(([source[t]], w1[:-1]))
        d = np.concatenate(([source_d[t]], e1[:-1]))
        f = np.where(three, (k["b0"] * (d - d1) + k["m1"] * v1) + k["m2"] * d1,
                     np.where(two, k["b0"] * d + k["m1"] * v1, np.where(one, k["b0"] * v, zero)))
        w2 = (f + k["c1"] * s1) + k["c2"] * s2
        w_one = w1 + (f + k["c1"] * w1)
        w = np.where(pole2, w2, np.where(pole1, w_one, f))
        e = np.where(pole1, f + k["c1"] * w1, w - w1)
        s1, s2 = (np.where(pole2, s1 + ((k["n"][0] * s1 + k["n"][1] * s2) + k["g"][0] * v), zero),
                  np.where(pole2, s2 + ((k["n"][2] * s1 + k["n"][3] * s2) + k["g"][1] * v), zero))
        v1, d1, w1, e1 = v, d, w, e
        if t >= count - 1:
            out[t - count + 1] = w[-1]
    return out


def float64_reference(realisation: Realisation, u: np.ndarray, input_polynomial=None) -> np.ndarray:
    """The realised model in double precision: polynomial -> delay -> (A, B, C, D)."""
    u = np.asarray(u, dtype=float)
    v = u if input_polynomial is None else sum(a * u ** (k + 1) for k, a in enumerate(input_polynomial))
    v = delay_signal(v, realisation.delay)
    return lti.simulate(realisation.A, realisation.B, realisation.C, realisation.D, v)
