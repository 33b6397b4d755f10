"""State-space realisations for code generation: balancing, truncation, re-discretisation.

The balanced realisation (Moore 1981; Laub et al. 1987, "square-root" algorithm,
:func:`sysid.core.lti.minimal_balanced_realisation`) has equal, diagonal
controllability and observability Gramians whose diagonal are the Hankel singular
values sigma_1 >= ... >= sigma_n. Truncating to the first r states bounds the error
by ||G - G_r||_inf <= 2 sum_{i>r} sigma_i (Enns' bound).

Re-discretisation goes through continuous time assuming a zero-order hold:
[[A, B], [0, 1]] = expm([[Ac, Bc], [0, 0]] T), so (Ac, Bc) come from the matrix
logarithm and the board-rate model from the matrix exponential at the new period.

Below the steps of firmware generation: the first design module the plan
(:mod:`codegen.plan`) runs; it imports only ``sysid.core`` and the errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from sysid.core.lti import minimal_balanced_realisation
from sysid.core.model import Model

from .errors import CodegenError, UnstableModelError

__all__ = ["Realisation", "realise", "rediscretise"]


@dataclass(frozen=True)
class Realisation:
    """A realised LTI core at the board rate plus what was done to obtain it.

    ``delay`` is in board samples; ``delay_error_s`` is the rounding error of the
    pure delay (board delay minus model delay, seconds) when the rates differ.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: float
    fs: float
    delay: int
    hankel_singular_values: np.ndarray
    truncated_from: int | None
    truncation_bound: float
    delay_error_s: float
    resampled_from: float | None


def rediscretise(A, B, fs_from: float, fs_to: float):
    """Zero-order-hold re-discretisation of (A, B) from rate fs_from to fs_to (Hz).

    Fails for a pole on the negative real axis, which has no real continuous-time
    counterpart under a zero-order hold.
    """
    n = A.shape[0]
    poles = np.linalg.eigvals(A)
    if np.any((np.abs(poles.imag) < 1e-12) & (poles.real <= 0)):
        raise CodegenError("model has a pole on the negative real axis; it cannot be re-discretised with a zero-order hold")
    M = np.zeros((n + 1, n + 1))
    M[:n, :n] = A
    M[:n, n:] = B
    M[n, n] = 1.0
    L = scipy.linalg.logm(M)
    if np.max(np.abs(np.imag(L))) > 1e-9 * max(1.0, np.max(np.abs(L))):
        raise CodegenError("matrix logarithm of the model is not real; cannot re-discretise")
    # L = [[Ac, Bc], [0, 0]] T_from; the board needs the same generator times T_to.
    L = np.real(L) * (fs_from / fs_to)
    E = scipy.linalg.expm(L)
    return E[:n, :n], E[:n, n:]


# Poles closer than this to the unit circle have no finite peak gain for scaling.
UNIT_CIRCLE_TOLERANCE = 1e-9


def realise(model: Model, fs: float | None = None, order: int | None = None, allow_unstable: bool = False) -> Realisation:
    """Balanced (optionally truncated) realisation of the model's LTI core at rate fs.

    ``fs=None`` (or the model's own rate) keeps the model's rate. The pure delay of
    d model samples becomes round(d fs / fs_model) board samples; the rounding
    error is returned as ``delay_error_s`` (stated in the manifest).
    Unstable models are refused unless ``allow_unstable``; they are then realised
    as given (no balancing, which needs the Gramians of a stable system).
    """
    if not model.stable and not allow_unstable:
        raise UnstableModelError(
            f"model is unstable (spectral radius {model.spectral_radius:.6f} >= 1); use --allow-unstable to generate anyway"
        )
    poles = np.linalg.eigvals(np.asarray(model.A, float)) if np.size(model.A) else np.zeros(0)
    on_circle = poles[np.abs(np.abs(poles) - 1.0) < UNIT_CIRCLE_TOLERANCE]
    if on_circle.size:
        # Infinite gain at the pole's frequency: no section scaling exists (even for an unstable
        # model, whose scaling uses the finite peak of its frequency response).
        p = on_circle[0]
        raise UnstableModelError(
            f"model has a pole on the unit circle (z = {p.real:.6g}{p.imag:+.6g}j): its gain at that frequency is "
            "infinite, so no fixed-point scaling exists even with --allow-unstable; re-identify the model or move "
            "the pole inside (e.g. radius 0.9999)")
    if order is not None and order < 1:
        raise CodegenError(f"order must be at least 1; found {order}")
    A, B, C, D = model.A, model.B, model.C, float(model.D[0, 0])
    if model.stable and model.order:
        balanced = minimal_balanced_realisation(A, B, C, D, order)
        A, B, C, D, hsv = balanced.A, balanced.B, balanced.C, balanced.D, balanced.hankel_singular_values
        truncated = model.order if A.shape[0] < model.order else None
        bound = float(2 * np.sum(hsv[A.shape[0]:]))
    else:
        if order is not None and order < model.order:
            raise CodegenError("balanced truncation needs a stable model")
        hsv, truncated, bound = np.zeros(0), None, 0.0
    board_fs = model.fs if fs is None else float(fs)
    if not (np.isfinite(board_fs) and board_fs > 0):
        raise CodegenError(f"--fs must be a positive sample rate in Hz; found {fs}")
    delay, delay_error, resampled = model.delay, 0.0, None
    if abs(board_fs - model.fs) > 1e-9 * model.fs:
        if A.shape[0]:
            A, B = rediscretise(A, B, model.fs, board_fs)
        delay = round(model.delay * board_fs / model.fs)
        delay_error = delay / board_fs - model.delay / model.fs
        resampled = model.fs
        if A.shape[0] and np.max(np.abs(np.linalg.eigvals(A))) >= 1 and not allow_unstable:
            raise UnstableModelError("re-discretised model is unstable")
    return Realisation(A=A, B=B, C=C, D=D, fs=board_fs, delay=delay, hankel_singular_values=np.asarray(hsv),
                       truncated_from=truncated, truncation_bound=bound, delay_error_s=float(delay_error),
                       resampled_from=resampled)
