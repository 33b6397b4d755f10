"""Removal of degenerate states from an identified model: states the data did not ask for.

An output-error fit of more poles than the data hold leaves the spare ones where they cost
nothing in the fitted band, and two kinds of them make a model useless downstream (fixed-point
code scales by the model's gains; a controller designed on it inherits states that carry
nothing the data saw):

- poles run to the block's radius bound (``output_error.decay_bound``) at z = 1 or z = -1,
  whose large residues cancel in band: a DC or Nyquist gain of 1e7 and Hankel singular values
  to match (random helmet 78, short session: the final refinement on the long block parked one
  pole at z = 1 and three at z = -1, Hankel singular values 1.4e7 and 2.4e6). They are dropped
  and the rest refitted on the block with the kept poles held (the refit kept only when its
  time-domain validation rms stays within ``min_gain`` of the model's);
- states that no balanced realisation of the full order holds (a cluster of close poles with
  huge cancelling residues, Hankel singular values down to 1e-17 of the largest; random helmet
  17, short: a balanced entry of 2.9e3): balanced from their chain realisation, those below 1e-10
  of the largest left out (``lti.balanced_truncation``, the frequency response kept within 1e-5
  of its peak).

Then the balanced model is truncated to the order the data ask for: the lowest order whose removed
Hankel singular values sum to at most TAIL_FRACTIONS of the largest (twice that bounds the change of
the frequency response, Moore 1981), kept when the time-domain validation rms rises by at most
TRUNCATION_GAIN (short sessions, the test's options: random helmet 0 order 16 -> 12, the true 12;
17 22 -> 17, the true 17; 79 23 -> 18, the true 18; the rms within 1 %), then refined by output error on
the block at its new order (a truncated model is not the least-squares fit of its order, which the 95 %
band of ``sysid.estimation.uncertainty`` assumes), the refinement kept when it validates within the same 1 %.

A model with none of these (its poles inside the bound, its realisation balanced, no Hankel singular
value small enough) is returned as it is, at the cost of two Lyapunov solves.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..core import lti
from ..core.thresholds import (BALANCED_TOLERANCE, BOUND_REFIT_ITERATIONS, NEGLIGIBLE_HSV, POLISH_ITERATIONS,
                               TAIL_FRACTIONS, TRUNCATION_GAIN)
from .order_search import distinct_start, without_freed_pole
from .output_error import BlockData, at_radius_bound, radius_bound_mask, refine_output_error

__all__ = ["Reduced", "is_balanced", "truncation_orders", "without_degenerate_states", "without_spare_pole"]


@dataclass
class Reduced:
    """A model (A, B, C, D) with its time-domain validation rms (FS) and what was removed ('' for nothing)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    rms: float
    removed: str = ""


def is_balanced(A, B, C) -> bool:
    """Whether both Gramians of the stable (A, B, C) equal one diagonal matrix within
    BALANCED_TOLERANCE of the largest Hankel singular value (``lti.balanced_realisation``'s result)."""
    return _balanced_hankel_values(A, B, C) is not None


def _balanced_hankel_values(A, B, C) -> np.ndarray | None:
    """The Hankel singular values of a balanced stable (A, B, C) (the diagonal its two Gramians share),
    in its states' order; None when it is not balanced (``is_balanced``)."""
    if np.asarray(A).shape[0] == 0:
        return np.zeros(0)
    try:
        wc, wo = lti.gramians(A, B, C)
    except (np.linalg.LinAlgError, ValueError):
        return None
    scale = max(np.max(np.abs(np.diag(wc))), 1e-300)
    off = np.max(np.abs(wc - np.diag(np.diag(wc)))) + np.max(np.abs(wc - wo))
    balanced = np.all(np.isfinite(wc)) and np.all(np.isfinite(wo)) and off <= BALANCED_TOLERANCE * scale
    return np.diag(wc) if balanced else None


def without_degenerate_states(A, B, C, D, rms: float, block: BlockData, validate: Callable[[Reduced], float],
                              min_gain: float, feedthrough: bool = False) -> Reduced:
    """The model without its degenerate states (module docstring), or as it is when it has none.

    ``rms`` is the model's time-domain validation rms and ``validate`` gives that of a candidate
    (an object with A, B, C, D); ``block`` is the data block the model was refined on (its radius
    bound decides which poles ran out of the data's reach, and the refit uses it).
    """
    current = Reduced(np.asarray(A, float), np.asarray(B, float), np.asarray(C, float), np.asarray(D, float), rms)
    poles = np.linalg.eigvals(current.A)
    bound = radius_bound_mask(poles, block)
    if np.any(bound) and np.count_nonzero(~bound) > 0:
        kept = poles[~bound]
        n = kept.size
        fit = refine_output_error(lti.real_block_diagonal(kept), np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)),
                                  block, feedthrough=feedthrough, max_iterations=BOUND_REFIT_ITERATIONS,
                                  noise_tolerance=True)
        refit = Reduced(fit.A, fit.B, fit.C, fit.D, np.inf,
                        f"{np.count_nonzero(bound)} poles at the radius bound dropped, the rest refitted")
        if not at_radius_bound(np.linalg.eigvals(fit.A), block):
            refit.rms = validate(refit)
            if refit.rms <= rms * (1 + min_gain):
                current = refit
    hsv = _balanced_hankel_values(current.A, current.B, current.C)
    if hsv is None:
        truncated = lti.balanced_truncation(current.A, current.B, current.C, current.D, tol=NEGLIGIBLE_HSV)
        if truncated is not None:
            removed = current.A.shape[0] - truncated[0].shape[0]
            note = (f"{removed} state{'s' if removed > 1 else ''} of negligible Hankel singular value left out" if removed
                    else "balanced")
            current = Reduced(*truncated, current.rms, "; ".join(filter(None, [current.removed, note])))
            hsv = _balanced_hankel_values(current.A, current.B, current.C)
    truncated = _truncated(current, hsv, validate)
    if truncated is current:
        return current
    # A truncated model is not the least-squares fit of its order: its error, below the validation's noise,
    # lies outside the 95 % band the output-error covariance gives (thesis-length random helmets 0, 5, 9,
    # 14: coverage 0.52-0.71 at median widths of 0.01 %). Refined on the block from there, it is.
    fit = refine_output_error(truncated.A, truncated.B, truncated.C, truncated.D, block, feedthrough=feedthrough,
                              max_iterations=POLISH_ITERATIONS, noise_tolerance=True)
    polished = Reduced(fit.A, fit.B, fit.C, fit.D, np.inf, truncated.removed + ", refined")
    if not at_radius_bound(np.linalg.eigvals(fit.A), block):
        polished.rms = validate(polished)
        if polished.rms <= truncated.rms * (1 + TRUNCATION_GAIN):
            return polished
    return truncated


def without_spare_pole(model: Reduced, band: tuple[float, float], block: BlockData,
                       validate: Callable[[Reduced], float], feedthrough: bool = False) -> Reduced:
    """``model`` without its out-of-band pole nearest the unit circle (``order_search.without_freed_pole``, ``band``
    in Hz), the rest refitted on ``block`` from their poles, when that validates within TRUNCATION_GAIN of its rms;
    else ``model`` as it is.

    A spare pole the fit ran toward z = -1 (or z = 1) out of the band may carry the model's largest Hankel singular
    value by residues that cancel in band, where balanced truncation, which drops the smallest, cannot reach it
    (random helmet 94 FF, short: 5 states, a pole at -0.99998 with Hankel singular value 5.1 beside the true mode's
    0.58 and 0.52; truncated to 3 states 1.05x, without that pole 2 states at the floor).
    """
    poles = without_freed_pole(np.linalg.eigvals(model.A), band, block.fs)
    if poles is None:
        return model
    # Coinciding poles (two at z = 0 from a rank-deficient start) split and run to the radius bound when refitted:
    # each replaced by a distinct real pole where the cost wants it first.
    poles = distinct_start(poles, block, feedthrough)
    n = poles.size
    fit = refine_output_error(lti.real_block_diagonal(poles), np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)),
                              block, feedthrough=feedthrough, max_iterations=POLISH_ITERATIONS, noise_tolerance=True)
    if at_radius_bound(np.linalg.eigvals(fit.A), block):
        return model
    refit = Reduced(fit.A, fit.B, fit.C, fit.D, np.inf, "; ".join(filter(None, [model.removed,
                                                                                "an out-of-band pole dropped"])))
    refit.rms = validate(refit)
    return refit if refit.rms <= model.rms * (1 + TRUNCATION_GAIN) else model


def truncation_orders(hsv: np.ndarray) -> list[int]:
    """For each of TAIL_FRACTIONS the lowest order k whose removed Hankel singular values sum to at most
    that fraction of the largest, sum_{i>k} sigma_i <= f sigma_1 (``hsv`` largest first); distinct orders
    below the full one, lowest first."""
    hsv = np.asarray(hsv, dtype=float)
    tail = np.append(np.cumsum(hsv[::-1])[::-1], 0.0)  # tail[k] = sum of hsv[k:]
    orders = {int(np.argmax(tail <= f * hsv[0])) for f in TAIL_FRACTIONS}
    return sorted(k for k in orders if 0 < k < hsv.size)


def _truncated(current: Reduced, hsv: np.ndarray | None, validate: Callable[[Reduced], float]) -> Reduced:
    """``current`` truncated to the lowest of its ``truncation_orders`` whose validation rms is within
    TRUNCATION_GAIN of its own; as it is when none is, or when it is not balanced (``hsv``, its Hankel
    singular values from ``_balanced_hankel_values``, None)."""
    if current.A.shape[0] < 2 or hsv is None:
        return current
    for order in truncation_orders(np.sort(hsv)[::-1]):
        truncated = lti.balanced_truncation(current.A, current.B, current.C, current.D, order=order)
        if truncated is None:
            continue
        candidate = Reduced(*truncated, np.inf)
        candidate.rms = validate(candidate)
        if candidate.rms <= current.rms * (1 + TRUNCATION_GAIN):
            note = f"balanced truncation {current.A.shape[0]} -> {order}"
            candidate.removed = "; ".join(filter(None, [current.removed, note]))
            return candidate
    return current
