"""Prediction of output round-off noise, coefficient error and overflow margins.

The figures are referred to a full-scale output sine (power 1/2 FS^2), the usual
"dynamic range" of a filter implementation, so they read as the noise floor the
variant adds below full scale:

* coefficient error: a sine anywhere in the validation band (20 Hz-4 kHz, design
  reference) sees the relative error |H_q - H| / |H| of the quantised cascade H_q;
  the worst one over the band is SNR_c = -20 log10 max_band |H_q - H| / |H|;
* round-off: each quantiser of step q injects white noise of variance q^2/12
  (Widrow & Kollar 2008, ch. 5) shaped by N_k(z) = Q(z) / A_k(z) prod_{j>k} H_j(z)
  up to the output, where Q = 1 - z^-1 with error feedback and 1 otherwise, so
  P_r = sum_k q^2/12 (1/pi) int_0^pi |N_k|^2 dw; float32 round-off is modelled as
  relative noise of variance 2^-48/3 per operation on the power of the operation's
  result, shaped by the path from where it enters to the output (:func:`predict_float32`
  for the generated forms, at the band's worst frequency for the loudest sine the filter
  takes there, since a relative noise follows the signal; CMSIS-DSP's DF2T on each
  section's output power);
  the Q15 output quantiser adds (2^-15)^2 / 12; SNR_r = 10 log10(0.5 / P_r).

The white-noise model of the Q15 quantisers is a steady state: the error-feedback residues start at
their mean (``codegen.fixedpoint.EFB_RESIDUE_AT_REST``), so a filter started from rest has no start
transient (started at 0 they rang every section's 1 / A_k unshaped: 718 times the prediction over
0.4 s on the seed pair's W, poles at 0.9986-0.9992). It assumes each quantiser's residue is white,
which needs its input to move by about a step per sample or more: a pole pair at 0.9992 and 4 Hz whose
output is 640 steps rms at 4 Hz (0.3 steps per sample; noise at -72 dBFS into a cascade of 60 dB peak
gain) gave 3 times the predicted round-off, the first-order shaper's idle tones on the resonance.

The predicted SNR combines both, 1/snr = 1/snr_c + 1/snr_r (linear ratios).
Overflow margins are given per node as 20 log10(1 / peak gain) for a full-scale
sine (L-infinity) and for the worst-case input (L1 norm of the impulse response).

Below the steps of firmware generation: the targets' variants predict with it and the
plan records its margins; it imports only the sections.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .sections import Cascade, Section, cascade_response, impulse_l1, peak_grid

__all__ = [
    "BAND_HZ",
    "Prediction",
    "fixed_roundoff_terms",
    "float32_roundoff_terms",
    "node_margins",
    "predict_cmsis",
    "predict_cmsis_f32",
    "predict_fixed",
    "predict_float32",
]

BAND_HZ = (20.0, 4000.0)
Q15_NOISE = 2.0**-30 / 12
Q31_STEP = 2.0**-31


@dataclass(frozen=True)
class Prediction:
    """Predicted SNRs (dB) of one variant against a full-scale output sine; P_r in FS^2."""

    roundoff_power: float
    coefficient_snr_db: float
    roundoff_snr_db: float
    snr_db: float

    def as_dict(self) -> dict:
        """JSON-ready figures; an SNR without any error (infinite) becomes None."""
        return {k: (float(v) if np.isfinite(v) else None) for k, v in self.__dict__.items()}


def _db(ratio: float) -> float:
    return float(10 * np.log10(ratio)) if ratio > 0 else float("inf")


def _grids(cascade: Cascade, fs: float):
    poles = [p for s in cascade.sections for p in s.poles]
    w = peak_grid(poles, points=32768)
    lo, hi = (2 * np.pi * f / fs for f in BAND_HZ)
    band = np.linspace(lo, min(hi, 0.99 * np.pi), 8192)
    return w, band


def _noise_gain(sections, k: int, w: np.ndarray, shaping: bool) -> float:
    """(1/pi) int_0^pi |N_k(e^jw)|^2 dw for a quantiser at the output of section k."""
    section = sections[k]
    zi = np.exp(-1j * w)
    response = 1.0 / (section.a[0] + section.a[1] * zi + section.a[2] * zi**2)
    if shaping:
        response = response * (1 - zi)
    for later in sections[k + 1:]:
        response = response * later.response(w)
    return float(np.trapezoid(np.abs(response) ** 2, w) / np.pi)


def _assemble(cascade: Cascade, quantised, fs: float, roundoff: float) -> Prediction:
    _, band = _grids(cascade, fs)
    exact = cascade_response(cascade.sections, band)
    approx = cascade_response(quantised, band)
    relative = float(np.max(np.abs(approx - exact) / np.maximum(np.abs(exact), 1e-300)))
    snr_c = _db(1.0 / relative**2) if relative > 0 else float("inf")
    snr_r = _db(0.5 / roundoff)
    combined = -_db(10 ** (-snr_c / 10) + 10 ** (-snr_r / 10))
    return Prediction(roundoff_power=roundoff, coefficient_snr_db=snr_c, roundoff_snr_db=snr_r, snr_db=combined)


def predict_fixed(cascade: Cascade, design, fs: float) -> Prediction:
    """Prediction for the Q15 variant of :mod:`codegen.fixedpoint`."""
    w, _ = _grids(cascade, fs)
    realised = _realised_fixed(design)
    roundoff = Q15_NOISE + sum(_fixed_terms(realised, design, w))
    return _assemble(cascade, realised, fs, roundoff)


def fixed_roundoff_terms(cascade: Cascade, design, fs: float) -> list[float]:
    """Per section of the Q15 variant, the round-off power (FS^2) its quantiser puts at the output (the terms
    :func:`predict_fixed` sums)."""
    w, _ = _grids(cascade, fs)
    return _fixed_terms(_realised_fixed(design), design, w)


def _realised_fixed(design) -> list[Section]:
    """The Q15 variant's sections as they compute, the input polynomial's exponent in the first."""
    realised = [s.realised() for s in design.sections]
    if design.polynomial_exponent:
        first = realised[0]
        realised[0] = Section(b=tuple(v / 2.0**design.polynomial_exponent for v in first.b), a=first.a,
                              poles=first.poles, zeros=first.zeros)
    return realised


def _fixed_terms(realised, design, w: np.ndarray) -> list[float]:
    shaping = design.quantiser == "efb"
    # Section k's output lies on a grid of 2^g_k Q31 LSBs (codegen.fixedpoint).
    return [(Q31_STEP * 2.0**section.guard) ** 2 / 12 * _noise_gain(realised, k, w, shaping)
            for k, section in enumerate(design.sections)]


def _float_prediction(cascade: Cascade, realised, fs: float) -> Prediction:
    """float32 round-off (relative, per operation) plus the realised sections' coefficient error."""
    w, band = _grids(cascade, fs)
    amplitude = 1.0 / float(np.max(np.abs(cascade_response(cascade.sections, band))))
    roundoff = 0.0
    for k, section in enumerate(cascade.sections):
        node_power = amplitude**2 / 2 * float(np.mean(np.abs(cascade_response(cascade.sections, band, k + 1)) ** 2))
        operations = 3 + 2 * section.order
        roundoff += operations * 2.0**-48 / 3 * node_power * _noise_gain(realised, k, w, False)
    return _assemble(cascade, realised, fs, roundoff)


def _state_responses(section, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(zI - A)^-1 g and c (zI - A)^-1 row by row for a two-pole float32 section (A = I + N), at z (arrays of 2 x len(z))."""
    A = np.eye(2) + np.array(section.n, float).reshape(2, 2)
    g, c = np.array(section.g, float), np.array(section.c, float)
    det = (z - A[0, 0]) * (z - A[1, 1]) - A[0, 1] * A[1, 0]
    # adj(zI - A) = [[z - A11, A01], [A10, z - A00]].
    forward = np.array([(z - A[1, 1]) * g[0] + A[0, 1] * g[1], A[1, 0] * g[0] + (z - A[0, 0]) * g[1]]) / det
    backward = np.array([c[0] * (z - A[1, 1]) + c[1] * A[1, 0], c[0] * A[0, 1] + c[1] * (z - A[0, 0])]) / det
    return forward, backward


def predict_float32(cascade: Cascade, design, fs: float) -> Prediction:
    """Prediction for the float32 variant of :mod:`codegen.float32`.

    Each float32 operation adds relative noise of variance 2^-48/3 on the power of its result.
    A relative noise follows the signal, so it is taken at every frequency of the band for the
    loudest sine the filter takes there (a full-scale input, or the input that drives the output
    to full scale where the gain exceeds 1), referred to a full-scale output like the fixed
    point's, and the worst frequency counts. A
    two-pole section (balanced state space): D x and the output sum go straight on, each
    state's increment and accumulation reach the output through c (zI - A)^-1 e_i. Other
    sections: the numerator's operations on f = b(z) x and a one-pole section's on its
    difference and sample reach it through 1 / a(z). The difference e = w - w1 and the cascade
    input's difference count on their own powers. Every path continues through the sections
    after it.
    """
    realised = [s.realised() for s in design.sections]
    # The worst sine of the band.
    terms = _float32_terms(cascade, design, realised, fs)
    return _assemble(cascade, realised, fs, float(np.max(np.sum(terms, axis=0))))


def float32_roundoff_terms(cascade: Cascade, design, fs: float) -> list[float]:
    """Per section of the float32 variant, the round-off power (FS^2) it puts at the output at the band's worst
    frequency for :func:`predict_float32` (the cascade input's own term left out)."""
    terms = _float32_terms(cascade, design, [s.realised() for s in design.sections], fs)
    worst = int(np.argmax(np.sum(terms, axis=0)))
    return [float(v) for v in terms[1:, worst]]


def _float32_terms(cascade: Cascade, design, realised, fs: float) -> np.ndarray:
    """(1 + sections, band points): the float32 round-off power at the output per band frequency of the cascade
    input's difference and of each section (:func:`predict_float32`; ``realised``: the design's sections as they
    compute)."""
    w, band = _grids(cascade, fs)
    sections = list(cascade.sections)
    # At each band frequency the loudest sine the filter takes: full scale at the input, or less where the gain
    # would drive the output beyond full scale (amplitude 1 / |H|); its noise is referred to a full-scale output.
    amplitude = np.minimum(1.0, 1.0 / np.maximum(np.abs(cascade_response(sections, band)), 1e-300))
    z_band, z = np.exp(1j * band), np.exp(1j * w)
    relative = 2.0**-48 / 3

    def power(response) -> np.ndarray:
        return amplitude**2 / 2 * np.abs(response) ** 2

    def gain(response) -> float:
        return float(np.trapezoid(np.abs(response) ** 2, w) / np.pi)

    terms = [relative * power(1 - 1 / z_band) * gain(cascade_response(sections, w))]
    for k, (section, floating) in enumerate(zip(sections, design.sections)):
        later = cascade_response(sections[k + 1:], w)
        before = cascade_response(sections, band, k)
        out = before * section.response(band)
        f = out * np.polyval(list(section.a)[::-1], 1 / z_band)
        numerator_ops = max(0, 2 * sum(1 for v in floating.b[: floating.taps] if v != 0.0) - 1) + (floating.taps == 3)
        own = realised[k]
        through_poles = gain(later / np.polyval(list(own.a)[::-1], 1 / z))
        difference = relative * power(out * (1 - 1 / z_band)) * gain(later)
        if floating.order == 2:
            # The state space of the whole section: D x and the output sum go straight on, the states'
            # rounding through c (zI - A)^-1 e_i.
            forward, _ = _state_responses(floating, z_band)
            _, backward = _state_responses(floating, z)
            output_ops = 1 + 2 * sum(1 for v in floating.c if v != 0.0)
            term = relative * (output_ops * power(out) * gain(later)) + difference
            for i in range(2):
                state = before * forward[i]
                count = sum(1 for v in floating.n[2 * i: 2 * i + 2] if v != 0.0) + (floating.g[i] != 0.0)
                injected = max(0, 2 * count - 1) * power(state * (z_band - 1)) + power(state)
                term = term + relative * injected * gain(backward[i] * later)
        else:
            term = relative * numerator_ops * power(f) * through_poles
            if floating.order == 1:
                feedback_ops = 2 if floating.c[0] != 0.0 else 0
                term = term + relative * (feedback_ops * power(out * (1 - 1 / z_band)) + power(out)) * through_poles
            else:
                term = term + difference
        terms.append(term)
    return np.array(terms)


def predict_cmsis_f32(cascade: Cascade, tables, fs: float) -> Prediction:
    """Prediction for CMSIS-DSP's float32 DF2T kernel with the float tables {b0, b1, b2, -a1, -a2}."""
    realised = [Section(b=tuple(row[:3]), a=(1.0, -row[3], -row[4]), poles=(), zeros=())
                for row in tables.f32_coefficients]
    return _float_prediction(cascade, realised, fs)


def predict_cmsis(cascade: Cascade, tables, fs: float) -> Prediction:
    """Prediction for the CMSIS-DSP fixed-point kernel ``tables.kernel`` with its tables.

    Every kernel floors each stage's output, a noise of variance q^2/12 plus a mean
    of -q/2 that the following gain at DC amplifies, with q = 2^-31 (Q31 kernels)
    or 2^-15 (Q15 kernel). In the ``q15`` and ``q31`` kernels the floored output is
    also the stage's feedback state, so the noise passes through 1/A_k; the
    ``q31x64`` kernel feeds back 64-bit states, so its Q31 floor only reaches the
    later stages (its own 2^-63 rounding is negligible). The Q31 kernels' output
    is finally rounded to Q15.
    """
    w, _ = _grids(cascade, fs)
    if tables.kernel == "q15":
        rows, scale, step = tables.q15_coefficients, 2.0 ** (tables.q15_post_shift - 15), 2.0**-15
    else:
        rows, scale, step = tables.q31_coefficients, 2.0 ** (tables.post_shift - 31), Q31_STEP
    realised = []
    for row in rows:
        b0, b1, b2, na1, na2 = (v * scale for v in row)
        realised.append(Section(b=(b0, b1, b2), a=(1.0, -na1, -na2), poles=(), zeros=()))
    if any(np.max(np.abs(np.roots(s.a)), initial=0.0) >= 1.0 for s in realised):
        # Coefficient rounding moved a pole onto or outside the unit circle: unusable.
        return Prediction(roundoff_power=float("inf"), coefficient_snr_db=float("-inf"),
                          roundoff_snr_db=float("-inf"), snr_db=float("-inf"))
    roundoff = 0.0 if tables.kernel == "q15" else Q15_NOISE
    up = 1.0 if tables.kernel == "q15" else 2.0**tables.output_shift
    if up != 1.0:
        # The Q31 tables' last stage is scaled by 2^-output_shift; the output conversion undoes it.
        last = realised[-1]
        realised[-1] = replace(last, b=tuple(v * up for v in last.b))
    for k in range(len(realised)):
        later = realised[k + 1:]
        if tables.kernel == "q31x64":
            gain = float(np.trapezoid(np.abs(cascade_response(later, w)) ** 2, w) / np.pi)
            dc = abs(cascade_response(later, np.zeros(1))[0])
        else:
            gain = _noise_gain(realised, k, w, False)
            dc = abs(cascade_response(later, np.zeros(1))[0] / np.polyval(realised[k].a[::-1], 1.0))
        if k == len(realised) - 1:
            gain, dc = gain * up**2, dc * up  # the last stage's floor is scaled up with it
        roundoff += step**2 / 12 * gain + (step / 2 * dc) ** 2
    return _assemble(cascade, realised, fs, roundoff)


def node_margins(cascade: Cascade) -> list[dict]:
    """Per section output: peak gain and overflow margin (dB) for sine and worst-case inputs."""
    poles = [p for s in cascade.sections for p in s.poles]
    w = peak_grid(poles, points=16384)
    stable = all(abs(p) < 1 for p in poles)
    rows = []
    for k in range(len(cascade.sections)):
        linf = float(np.max(np.abs(cascade_response(cascade.sections, w, k + 1))))
        # An unstable cascade has no finite worst case.
        l1 = impulse_l1(cascade.sections[: k + 1], poles) if stable else None
        rows.append({"section": k, "peak_gain_sine": linf, "margin_sine_db": float(-20 * np.log10(linf)),
                     "peak_gain_worst_case": l1,
                     "margin_worst_case_db": None if l1 is None else float(-20 * np.log10(l1))})
    return rows
