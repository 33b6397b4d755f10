"""Python references of the generated filters: bit-exact fixed point, float32, float64.

:func:`fixed_reference` is the specification of the generated Q15 code: integer
for integer the same operations (numpy int64 for the feed-forward sums, Python
integers for the recursion), so the C output must agree to 0 LSB.
:func:`float32_reference` performs the float32 operations of the generated float
code in the same order. :func:`float64_reference` is the realised model in double
precision, the yardstick of the signal-to-noise ratios.

The cascade is processed section after section over the whole signal: each
section's output depends only on its input sequence, so this equals the C code's
sample-by-sample interleaving.
"""

from __future__ import annotations

import numpy as np

from sysid import lti

from .fixedpoint import FixedDesign
from .float32 import FloatDesign
from .realise import Realisation

__all__ = ["delay_signal", "fixed_reference", "float32_reference", "float64_reference", "from_q15", "to_q15"]

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


def fixed_reference(design: FixedDesign, u: np.ndarray) -> np.ndarray:
    """Bit-exact output (int16) of the generated Q15 filter for Q15 input u, from rest."""
    u = delay_signal(np.asarray(u, dtype=np.int16).astype(np.int64), design.delay)
    if design.polynomial is None:
        x = u * 65536
    else:
        # Horner in Q31 with floor shifts: acc = P_k + (acc u) >> 15, then x = (acc u) >> 15.
        acc = np.full(u.shape, design.polynomial[-1], dtype=np.int64)
        for p in design.polynomial[-2::-1]:
            acc = p + ((acc * u) >> 15)
        x = (acc * u) >> 15
    for section in design.sections:
        b0, b1, b2 = section.b
        forward = (b0 * x + b1 * _history(x, 1) + b2 * _history(x, 2)) >> section.b_align
        c1, c2 = section.c
        shift, c_align, order = section.shift, section.c_align, section.order
        efb = design.quantiser == "efb"
        mask = (1 << shift) - 1
        half = 1 << (shift - 1)
        y = np.empty_like(x)
        y1 = y2 = e = 0
        for n, v in enumerate(forward.tolist()):
            acc = v + ((c1 * y1 + c2 * y2) >> c_align)
            if efb:
                acc += e
                e = acc & mask
            else:
                acc += half
            w = acc >> shift
            if order == 2:
                w += 2 * y1 - y2
            elif order == 1:
                w += y1
            out = INT32_MAX if w > INT32_MAX else max(w, INT32_MIN)
            y2, y1 = y1, out
            y[n] = out
        x = y
    return np.clip((x + 32768) >> 16, -32768, 32767).astype(np.int16)


def float32_reference(design: FloatDesign, u: np.ndarray) -> np.ndarray:
    """Output (float32) of the generated float filter for float32 input u, from rest."""
    f32 = np.float32
    u = delay_signal(np.asarray(u, dtype=f32), design.delay)
    if design.polynomial is None:
        x = u
    else:
        # Horner: v = a_K; v = a_k + v u; ...; x = v u (all float32).
        acc = np.full(u.shape, design.polynomial[-1], dtype=f32)
        for a in design.polynomial[-2::-1]:
            acc = f32(a) + acc * u
        x = acc * u
    two = f32(2.0)
    for section in design.sections:
        terms = [(f32(b), _history(x, lag)) for lag, b in enumerate(section.b) if b != 0.0]
        forward = terms[0][0] * terms[0][1] if terms else np.zeros_like(x)
        for b, xl in terms[1:]:
            forward = forward + b * xl
        c1, c2 = f32(section.c[0]), f32(section.c[1])
        use_c1, use_c2 = section.c[0] != 0.0, section.c[1] != 0.0
        y = np.empty_like(x)
        y1 = y2 = f32(0.0)
        for n, t in enumerate(forward):
            if use_c1:
                t = t + c1 * y1
            if use_c2:
                t = t + c2 * y2
            if section.order == 2:
                t = t + (two * y1 - y2)
            elif section.order == 1:
                t = t + y1
            y2, y1 = y1, t
            y[n] = t
        x = y
    return x


def float64_reference(realisation: Realisation, u: np.ndarray, input_polynomial=None) -> np.ndarray:
    """The realised model in double precision: polynomial -> delay -> (A, B, C, D)."""
    u = np.asarray(u, dtype=float)
    v = u if input_polynomial is None else sum(a * u ** (k + 1) for k, a in enumerate(input_polynomial))
    v = delay_signal(v, realisation.delay)
    return lti.simulate(realisation.A, realisation.B, realisation.C, realisation.D, v)
