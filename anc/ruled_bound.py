"""The causal feed-forward bound under the design's rules, by one Lagrange multiplier per region.

The causal Wiener bound (``anc.limits``) minimises the ear power in the band measure V, which outside
20 Hz-2 kHz is ``anc.limits.OUTSIDE_WEIGHT`` small. Where the chin path is faster than the drive path, or S
has zeros outside the unit circle, that filter buys attenuation in the bands with gain outside them, where the
recording's chin spectrum is at its floor (random pair 1/1001 of ``tests/control_cases``: 29.2 dB mean over
50 Hz-1 kHz with W's mean-square gain 80-100 dB above 2 kHz). A microphone's self-noise is what sits there, and
the design may not amplify it (``anc.feedforward``): no band with noise louder than without W, W's mean-square
gain per region outside the bands bounded. ``ruled_wiener`` is the same bound under those rules:

.. math::
    \\min_W J(W) = \\sum_k V \\Phi (|T + G W|^2 + R |W|^2)
    \\quad \\text{s.t.} \\quad E_b(W) \\le A\\, E_b(0) \\text{ (bands with noise)}, \\qquad
    \\frac{1}{n_r} \\sum_{k \\in r} |W_k|^2 \\le C \\text{ (regions outside the bands)},

with E_b(W) = sum over the band's bins of u + Phi |T + G W|^2 (the ear power, ``FeedforwardProblem.band_sum``),
A = 10^(limit / 10) the stated amplification limit and C = 10^(gain / 10). The Lagrangian with multipliers
mu_b, lambda_r >= 0 is a J of the same form with weight V + mu and penalty (V Phi R + lambda) / ((V + mu) Phi),
so its minimiser over causal W is ``anc.wiener.causal_wiener``'s. The problem is a convex quadratically
constrained program in W's causal impulse response, strictly feasible at W = 0, so strong duality holds (Boyd &
Vandenberghe, "Convex Optimization", 2004, sec. 5.2.3 and 5.5.3). The multipliers are raised while their
constraint is violated and lowered while it is slack, multiplicatively (a dual ascent in log-multipliers), until
the iterate is feasible and every constraint with a multiplier binds, to ``TOLERANCE_DB``. The filter returned is
the feasible iterate of least J; the dual function at the last multipliers bounds the optimum J from below, and
``gap_db`` states the distance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RuledBound", "ruled_wiener", "outside_gain_db", "TOLERANCE_DB", "MAX_ITERATIONS"]

# A constraint is kept, and a multiplier's constraint binds, to this (dB).
TOLERANCE_DB = 0.05
MAX_ITERATIONS = 300
# Multiplicative steps are the constraint's ratio to this power, within a factor of four either way.
_STEP_POWER = 0.7
_STEP_LIMIT = 4.0
# A multiplier this far below its starting value has left its constraint.
_RELEASED = 1e-9


@dataclass(frozen=True)
class RuledBound:
    """The bound's filter ``W`` on the problem's grid and how it was found: ``feasible`` (every rule kept to
    ``TOLERANCE_DB``; else the iterate of least violation), ``iterations``, ``gap_db`` (J of W over the dual
    function's value, dB; 0 at the optimum), ``binding`` the rules that hold it ("bands", "gain outside"),
    ``outside_gain_db`` W's largest mean-square gain in a region outside the bands (dB)."""

    W: np.ndarray
    feasible: bool
    iterations: int
    gap_db: float
    binding: tuple[str, ...]
    outside_gain_db: float


def outside_gain_db(problem, W: np.ndarray) -> float:
    """W's largest mean-square gain (dB) in a region outside the bands (``FeedforwardProblem.outside_gain``)."""
    return float(10.0 * np.log10(max(float(np.max(problem.outside_gain(W), initial=0.0)), 1e-300)))


def ruled_wiener(problem, max_amplification_db: float, max_gain_db: float) -> RuledBound:
    """The causal filter of least J under the design's rules (module docstring) for ``problem``, an
    ``anc.limits.FeedforwardProblem`` (W alone: T, the grid, the band measure and the floored chin spectrum)."""
    nb, regions = problem.bands, int(problem.region.max()) + 1
    V, phi, region = problem.band_measure, problem.phi, problem.region
    counts = np.maximum(np.bincount(region, minlength=regions), 1).astype(float)
    in_band = np.zeros(regions, bool)
    in_band[:nb] = problem.audible
    outside = np.zeros(regions, bool)
    outside[nb:] = True
    limit = np.where(in_band, 10.0 ** (max_amplification_db / 10.0) * problem.off,
                     counts * 10.0 ** (max_gain_db / 10.0))
    # Each multiplier starts at the size of what it is added to: the band's measure, the region's V Phi |G|^2.
    start = np.where(in_band, np.bincount(region, weights=V, minlength=regions) / counts,
                     np.bincount(region, weights=V * phi * np.abs(problem.G) ** 2, minlength=regions) / counts)
    start = np.maximum(start, np.finfo(float).tiny)
    ruled = in_band | outside
    multiplier = np.zeros(regions)
    tolerance = 10.0 ** (TOLERANCE_DB / 10.0)
    best = least_violating = None
    for iteration in range(1, MAX_ITERATIONS + 1):
        mu = np.where(in_band, multiplier, 0.0)[region]
        lam = np.where(outside, multiplier, 0.0)[region]
        weight = V + mu
        W = problem.wiener(effort=(V * phi * problem.effort + lam) / (weight * phi), weight=weight)
        error = np.abs(problem.H + problem.G * W) ** 2
        ear = problem.band_sum(problem.uu + phi * error)
        power = problem.band_sum(np.abs(W) ** 2)
        used = np.where(in_band, ear, np.where(outside, power, 0.0))
        ratio = np.where(ruled, used / limit, 0.0)
        cost = float(np.sum(V * phi * (error + problem.effort * np.abs(W) ** 2)))
        dual = cost + float(np.sum(np.where(ruled, multiplier * (used - limit), 0.0)))
        worst = float(np.max(ratio))
        if worst <= tolerance and (best is None or cost < best[0]):
            best = (cost, W)
        if least_violating is None or worst < least_violating[0]:
            least_violating = (worst, cost, W)
        active = multiplier > 0.0
        if worst <= tolerance and np.all(ratio[active] >= 1.0 / tolerance):
            break
        step = np.clip(ratio, 1.0 / _STEP_LIMIT, _STEP_LIMIT) ** _STEP_POWER
        multiplier = np.where(active, multiplier * step, np.where(ruled & (ratio > 1.0), start, 0.0))
        multiplier[multiplier < _RELEASED * start] = 0.0
    binding = tuple(name for name, where in (("bands", in_band), ("gain outside", outside))
                    if np.any(multiplier[where] > 0.0))
    feasible = best is not None
    cost, W = best if feasible else least_violating[1:]
    # The dual function at the last multipliers bounds every feasible J from below (weak duality).
    gap = 10.0 * np.log10(max(cost, 1e-300) / max(dual, 1e-300)) if dual > 0.0 else float("inf")
    return RuledBound(W, feasible, iteration, float(gap), binding, outside_gain_db(problem, W))
