"""Coefficient tables for CMSIS-DSP's biquad kernels and Python models of those kernels.

CMSIS-DSP (ARM) runs a cascade of direct-form-I stages with states
{x[n-1], x[n-2], y[n-1], y[n-2]} and coefficients {b0, b1, b2, A1, A2} divided by
2^postShift, where A1 = -a1 and A2 = -a2. The three fixed-point kernels the cmsis
target can use, as restated here from their documentation (and checked bit for
bit against the ``cmsisdsp`` package by the tests):

``q15`` (``arm_biquad_cascade_df1_q15``): Q15 samples and coefficients (stored
    {b0, 0, b1, b2, A1, A2}), acc = sum of products in 64 bits,
    y = sat16(acc >> (15 - postShift)).
``q31`` (``arm_biquad_cascade_df1_q31``): Q31 samples and coefficients,
    acc = sum of products (64-bit, wraps), y = (int32)(acc >> (31 - postShift)),
    which wraps too.
``q31x64`` (``arm_biquad_cas_df1_32x64_q31``): as ``q31`` but y[n-1], y[n-2] kept as
    64-bit states (acc << (postShift + 1)) multiplied by the Q31 A's in 32x64 bits:
    (y_lo A >> 32) + y_hi A with y_lo the unsigned low and y_hi the signed high
    word; the stage output is (int32)(acc >> (31 - postShift)).

Neither Q31 kernel saturates: a stage output beyond full scale wraps. For them the
cascade is scaled in the worst-case (l1) norm, so no stage output, including the
last, can exceed full scale for any input: the last stage is scaled down by
2^-output_shift and the Q31 -> Q15 conversion of the generated code multiplies that
back with saturation (:func:`q31_to_q15`). The postShift is also raised until the
64-bit accumulator cannot overflow (sum |row| < 2^(postShift + 1) with states below
full scale).

The float variant uses ``arm_biquad_cascade_df2T_f32`` (transposed direct form
II). The design reference measured 51-55 dB for the plain Q31 kernel on poles
this close to the unit circle and 87-90 dB for the 64-bit-state one.

Below the steps of firmware generation: a design module (it imports the sections and the
references) that the cmsis target runs; the host build takes its Q31 -> Q15 conversion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import PrecisionError
from .reference import delay_signal
from .sections import Cascade, impulse_l1

__all__ = [
    "KERNELS",
    "CmsisTables",
    "cmsis_q15_reference",
    "design_cmsis",
    "df2t_f32_reference",
    "q15_kernel",
    "q31_kernel",
    "q31_to_q15",
    "q31x64_kernel",
]

# Cheapest first: the plan takes the first kernel that meets the requested SNR.
KERNELS = ("q15", "q31", "q31x64")
KERNEL_FUNCTIONS = {"q15": "arm_biquad_cascade_df1_q15", "q31": "arm_biquad_cascade_df1_q31",
                    "q31x64": "arm_biquad_cas_df1_32x64_q31"}


@dataclass(frozen=True)
class CmsisTables:
    """Per-stage rows {b0, b1, b2, -a1, -a2} for each kernel, and the kernel in use.

    ``q31_coefficients`` (with ``post_shift``) serve the ``q31`` and ``q31x64``
    kernels, ``q15_coefficients`` (with ``q15_post_shift``) the ``q15`` kernel.
    The Q31 rows' last stage is scaled by 2^-``output_shift`` (undone, saturating,
    in the Q31 -> Q15 conversion).
    """

    kernel: str
    post_shift: int
    q31_coefficients: tuple[tuple[int, int, int, int, int], ...]
    q15_post_shift: int
    q15_coefficients: tuple[tuple[int, int, int, int, int], ...]
    f32_coefficients: tuple[tuple[float, float, float, float, float], ...]
    delay: int
    output_shift: int = 0


def _wrap(value: int, bits: int) -> int:
    """Two's-complement wrap-around of an integer to the given width."""
    half = 1 << (bits - 1)
    return ((value + half) % (1 << bits)) - half


def _quantise_rows(rows, bits: int) -> tuple[int, tuple]:
    """Smallest postShift making every coefficient fit Q(bits-1), and the rounded integers.

    For the 32-bit rows the postShift also keeps the 64-bit accumulator from wrapping:
    with states below full scale, |acc| < sum|row| 2^(62 - postShift) < 2^63.
    """
    largest = max(abs(v) for row in rows for v in row)
    post_shift = max(0, int(np.ceil(np.log2(largest))) if largest > 0 else 0)
    if largest >= 2.0**post_shift * (1 - 2.0 ** -(bits - 1)):
        post_shift += 1
    if bits == 32:
        while max(sum(abs(v) for v in row) for row in rows) >= 2.0 ** (post_shift + 1) * (1 - 2.0**-20):
            post_shift += 1
    scale = 2.0 ** (bits - 1 - post_shift)
    top = 2 ** (bits - 1)
    ints = tuple(tuple(int(np.clip(round(v * scale), -top, top - 1)) for v in row) for row in rows)
    return post_shift, ints


def _output_shift(cascade: Cascade, full_scale: float) -> int:
    """Smallest P with the cascade's worst-case (l1) gain times 2^-P below ``full_scale``."""
    poles = [p for s in cascade.sections for p in s.poles]
    if any(abs(p) >= 1 for p in poles):
        return 0  # no finite worst case (an unstable model, allowed explicitly)
    l1 = impulse_l1(cascade.sections, poles)
    return max(0, int(np.ceil(np.log2(l1 / full_scale)))) if l1 > 0 else 0


def design_cmsis(cascade: Cascade, delay: int, input_polynomial=None, kernel: str = "q31") -> CmsisTables:
    """Tables of the cascade in CMSIS order; each postShift is the smallest that fits all rows.

    ``cascade`` should be scaled in the l1 norm (:func:`codegen.sections.design_cascade`
    with ``scaling='l1'``) so the Q31 kernels' intermediate stages cannot wrap; the last
    Q31 stage is scaled by 2^-output_shift so it cannot either (see the module docstring).
    """
    if input_polynomial is not None:
        raise PrecisionError("the cmsis target does not implement an input polynomial; use --target generic")
    if kernel not in KERNELS:
        raise PrecisionError(f"CMSIS kernel must be one of {', '.join(KERNELS)}; found {kernel!r}")
    rows = [(*s.b, -s.a[1], -s.a[2]) for s in cascade.sections]
    # 1 - 2^-10: room for the coefficient rounding of the Q31 tables.
    output_shift = _output_shift(cascade, 1 - 2.0**-10)
    down = 2.0**-output_shift
    q31_rows = rows[:-1] + [(rows[-1][0] * down, rows[-1][1] * down, rows[-1][2] * down, rows[-1][3], rows[-1][4])]
    post_shift, q31 = _quantise_rows(q31_rows, 32)
    q15_post_shift, q15 = _quantise_rows(rows, 16)
    f32 = tuple(tuple(float(np.float32(v)) for v in row) for row in rows)
    return CmsisTables(kernel=kernel, post_shift=post_shift, q31_coefficients=q31, q15_post_shift=q15_post_shift,
                       q15_coefficients=q15, f32_coefficients=f32, delay=int(delay), output_shift=output_shift)


def q15_kernel(tables: CmsisTables, x: np.ndarray) -> np.ndarray:
    """Output of CMSIS-DSP's Q15 DF1 cascade for Q15 input x, from rest."""
    signal = [int(v) for v in np.asarray(x, dtype=np.int64)]
    shift = 15 - tables.q15_post_shift
    for b0, b1, b2, a1, a2 in tables.q15_coefficients:
        x1 = x2 = y1 = y2 = 0
        out = []
        for xn in signal:
            yn = (b0 * xn + b1 * x1 + b2 * x2 + a1 * y1 + a2 * y2) >> shift
            yn = 32767 if yn > 32767 else max(yn, -32768)
            x2, x1, y2, y1 = x1, xn, y1, yn
            out.append(yn)
        signal = out
    return np.asarray(signal, dtype=np.int16)


def q31_kernel(tables: CmsisTables, x: np.ndarray) -> np.ndarray:
    """Output of CMSIS-DSP's Q31 DF1 cascade for Q31 input x, from rest."""
    signal = [int(v) for v in np.asarray(x, dtype=np.int64)]
    shift = 31 - tables.post_shift
    for b0, b1, b2, a1, a2 in tables.q31_coefficients:
        x1 = x2 = y1 = y2 = 0
        out = []
        for xn in signal:
            acc = _wrap(b0 * xn + b1 * x1 + b2 * x2 + a1 * y1 + a2 * y2, 64)
            yn = _wrap(acc >> shift, 32)
            x2, x1, y2, y1 = x1, xn, y1, yn
            out.append(yn)
        signal = out
    return np.asarray(signal, dtype=np.int32)


def q31x64_kernel(tables: CmsisTables, x: np.ndarray) -> np.ndarray:
    """Output of CMSIS-DSP's 32x64 (64-bit state) Q31 DF1 cascade for Q31 input x, from rest."""
    signal = [int(v) for v in np.asarray(x, dtype=np.int64)]
    up = tables.post_shift + 1
    low = (1 << 32) - 1
    for b0, b1, b2, a1, a2 in tables.q31_coefficients:
        x1 = x2 = y1 = y2 = 0
        out = []
        for xn in signal:
            acc = b0 * xn + b1 * x1 + b2 * x2
            # 32x64 products: low word unsigned, shifted down 32 bits, plus the signed high word.
            acc += (((y1 & low) * a1) >> 32) + (y1 >> 32) * a1
            acc += (((y2 & low) * a2) >> 32) + (y2 >> 32) * a2
            acc = _wrap(acc, 64)
            x2, x1, y2, y1 = x1, xn, y1, _wrap(acc << up, 64)
            out.append(_wrap(acc >> (32 - up), 32))
        signal = out
    return np.asarray(signal, dtype=np.int32)


def q31_to_q15(y: np.ndarray, output_shift: int) -> np.ndarray:
    """The generated code's Q31 kernel output -> Q15: times 2^output_shift, round to nearest, saturate."""
    r = (np.asarray(y, np.int64) * (1 << output_shift) + 32768) >> 16
    return np.clip(r, -32768, 32767).astype(np.int16)


def cmsis_q15_reference(tables: CmsisTables, u: np.ndarray) -> np.ndarray:
    """The generated cmsis Q15 process(): delay, then the kernel (Q31 kernels: x << 16 in, rounded to Q15 out)."""
    u = delay_signal(np.asarray(u, dtype=np.int16), tables.delay)
    if tables.kernel == "q15":
        return q15_kernel(tables, u)
    kernel = q31_kernel if tables.kernel == "q31" else q31x64_kernel
    return q31_to_q15(kernel(tables, u.astype(np.int64) * 65536), tables.output_shift)


def df2t_f32_reference(tables: CmsisTables, u: np.ndarray) -> np.ndarray:
    """Transposed direct form II in float32 with the float tables (delay in front)."""
    f32 = np.float32
    signal = delay_signal(np.asarray(u, dtype=f32), tables.delay)
    for b0, b1, b2, a1, a2 in tables.f32_coefficients:
        b0, b1, b2, a1, a2 = (f32(v) for v in (b0, b1, b2, a1, a2))
        d1 = d2 = f32(0.0)
        out = np.empty_like(signal)
        for n, xn in enumerate(signal):
            yn = b0 * xn + d1
            d1 = b1 * xn + a1 * yn + d2
            d2 = b2 * xn + a2 * yn
            out[n] = yn
        signal = out
    return signal
