"""Model structures for physical effects: series factors, resonant modes, input polynomials.

The JSON contract (design.md, "The model") keeps a path model as
[input polynomial] -> [z^-delay] -> (A, B, C, D). A resonance or a high-/low-pass
factor therefore becomes part of (A, B, C, D) by series connection; ``history``
records that it was added. The factors here are the discrete-time filters of
effects.md:

- high-pass, first order: zero at z = 1, pole at p = 1 - 2 pi fc / fs,
  H(z) = (1 + p)/2 (1 - z^-1)/(1 - p z^-1) (unity gain at fs/2);
  second order: Butterworth.
- low-pass: Butterworth of order 1 or 2 (bilinear transform).
- resonance: the peaking biquad of Bristow-Johnson's audio-EQ cookbook, gain
  10^(gain_db/20) at f0, bandwidth f0/Q, unity far from f0 (a second-order mode).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.signal

__all__ = ["StateSpace", "series", "tf_to_statespace", "highpass_factor", "lowpass_factor", "resonance_factor",
           "factor_coefficients", "factor_response", "mode_block",
           "with_states"]

StateSpace = tuple  # (A, B, C, D) of a SISO system, numpy arrays of shapes (n,n), (n,1), (1,n), (1,1)


def tf_to_statespace(b, a) -> StateSpace:
    """(A, B, C, D) of b(z)/a(z) with coefficients in powers of z^-1."""
    A, B, C, D = scipy.signal.tf2ss(np.asarray(b, float), np.asarray(a, float))
    n = A.shape[0]
    return (np.asarray(A, float).reshape(n, n), np.asarray(B, float).reshape(n, 1),
            np.asarray(C, float).reshape(1, n), np.asarray(D, float).reshape(1, 1))


def series(first: StateSpace, second: StateSpace) -> StateSpace:
    """The system u -> first -> second; state [x_first; x_second]."""
    A1, B1, C1, D1 = first
    A2, B2, C2, D2 = second
    n1, n2 = A1.shape[0], A2.shape[0]
    A = np.block([[A1, np.zeros((n1, n2))], [B2 @ C1, A2]])
    B = np.vstack([B1, B2 @ D1])
    C = np.hstack([D2 @ C1, C2])
    return A, B, C, D2 @ D1


def highpass_factor(corner_hz: float, fs: float, order: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of the high-pass factor (see the module docstring)."""
    if order == 1:
        p = 1.0 - 2.0 * np.pi * corner_hz / fs
        return np.array([1.0, -1.0]) * (1.0 + p) / 2.0, np.array([1.0, -p])
    return scipy.signal.butter(order, corner_hz, "highpass", fs=fs)


def lowpass_factor(corner_hz: float, fs: float, order: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of a Butterworth low-pass of the given order and -3 dB corner (Hz)."""
    return scipy.signal.butter(order, corner_hz, "lowpass", fs=fs)


def resonance_factor(f0_hz: float, q: float, gain_db: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of the peaking biquad: |H| = 10^(gain_db/20) at f0, unity at DC and fs/2."""
    big_a = 10.0 ** (gain_db / 40.0)
    w0 = 2.0 * np.pi * f0_hz / fs
    alpha = np.sin(w0) / (2.0 * q)
    b = np.array([1 + alpha * big_a, -2 * np.cos(w0), 1 - alpha * big_a])
    a = np.array([1 + alpha / big_a, -2 * np.cos(w0), 1 - alpha / big_a])
    return b / a[0], a / a[0]


def factor_coefficients(kind: str, params: dict, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of a named factor: ``resonance`` (f0_hz, q, gain_db), ``highpass`` or ``lowpass`` (corner_hz, order)."""
    if kind == "resonance":
        return resonance_factor(params["f0_hz"], params["q"], params["gain_db"], fs)
    if kind == "highpass":
        return highpass_factor(params["corner_hz"], fs, params["order"])
    if kind == "lowpass":
        return lowpass_factor(params["corner_hz"], fs, params["order"])
    raise ValueError(f"unknown factor {kind!r}")


def factor_response(b, a, frequencies_hz, fs: float) -> np.ndarray:
    """Complex response of b(z)/a(z) at frequencies in Hz."""
    # Horner in z^-1 (as scipy.signal.freqz with explicit frequencies, without its overhead).
    z1 = np.exp(-2j * np.pi * np.asarray(frequencies_hz, float) / fs)
    return np.polyval(np.asarray(b, float)[::-1], z1) / np.polyval(np.asarray(a, float)[::-1], z1)


def with_states(A, B, C, *blocks) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C) with new state blocks on the diagonal, not yet coupled to the input or output.

    The start of a refit that adds dynamics: the response is unchanged until the
    refit gives the new states their input and output weights.
    """
    added = sum(np.shape(b)[0] for b in blocks)
    return (scipy.linalg.block_diag(A, *blocks), np.vstack([B, np.zeros((added, 1))]),
            np.hstack([C, np.zeros((1, added))]))


def mode_block(f0_hz: float, q: float, fs: float) -> np.ndarray:
    """2x2 real block with the poles of a mode at f0 (Hz) and quality factor Q.

    The pole radius follows from the -3 dB bandwidth f0/Q: r = exp(-pi f0 / (Q fs)).
    """
    r = np.exp(-np.pi * f0_hz / (q * fs))
    theta = 2.0 * np.pi * f0_hz / fs
    return np.array([[r * np.cos(theta), r * np.sin(theta)], [-r * np.sin(theta), r * np.cos(theta)]])

