"""A convex quadratic minimised over real coefficients while complex affine responses stay in discs.

The feedback designs (``anc.feedback_bound``) are all of one form: with a filter linear in
real coefficients c, every frequency response the design bounds is affine in c, and every
bound is a disc in the complex plane,

.. math::
    \\min_c \\; c^T P c + 2 q^T c
    \\quad \\text{subject to} \\quad |u_k + v_k^T c| \\le \\rho_k, \\; k = 1 .. m,

(P symmetric positive semi-definite; v_k complex rows). Each constraint is a second-order
cone in c, so the problem is convex and its minimum global. It is solved by the barrier
method (Boyd & Vandenberghe, "Convex Optimization", 2004, sec. 11.3, algorithm 11.1): Newton
steps on t J(c) - sum_k log(rho_k^2 - |u_k + v_k^T c|^2) with a backtracking line search
kept strictly inside every disc, t raised ``MU`` times per round until the duality gap m / t
is below ``tolerance`` of the objective's scale. The discs are exact (no polygon of
linear sides), and a Newton step costs three products of the m x n constraint matrices,
so thousands of discs and hundreds of coefficients solve in seconds with numpy alone.

The start must lie strictly inside every disc (``c0``; zero by default: every u_k strictly
inside its disc).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from threadpoolctl import threadpool_limits

__all__ = ["DiscProgram", "solve_disc_program", "MU"]

# The barrier weight's growth per round (Boyd & Vandenberghe sec. 11.3.1: 10-20 is typical).
MU = 20.0
_NEWTON_STEPS = 80
_ALPHA, _BETA = 0.25, 0.5
_CENTRING = 1e-10


@dataclass(frozen=True)
class DiscProgram:
    """min c'Pc + 2q'c subject to |offsets_k + rows_k . c| <= radii_k (module docstring)."""

    P: np.ndarray
    q: np.ndarray
    rows: np.ndarray       # (m, n) complex
    offsets: np.ndarray    # (m,) complex
    radii: np.ndarray      # (m,) > 0

    def objective(self, c: np.ndarray) -> float:
        return float(c @ self.P @ c + 2.0 * self.q @ c)

    def slack(self, c: np.ndarray) -> np.ndarray:
        """rho_k^2 - |u_k + v_k . c|^2 (> 0 strictly inside every disc)."""
        r = self.offsets + self.rows @ c
        return self.radii**2 - (r.real**2 + r.imag**2)


def solve_disc_program(program: DiscProgram, c0: np.ndarray | None = None, tolerance: float = 1e-7,
                       t0: float | None = None) -> np.ndarray:
    """The minimiser c of ``program`` (module docstring), from the strictly feasible start ``c0``.

    ``tolerance``: the final duality gap m / t relative to the objective's scale (its value at the
    start, at least 1). ``t0``: the first barrier weight (default: m over the scale, so that objective
    and barrier weigh alike), larger to resume from a point already near the optimum. One BLAS
    thread: the matrices are of hundreds of rows, where a second thread on a busy machine made
    each Newton step a hundred times slower (0.13 s against 0.5 ms for a 160 x 160 solve).
    """
    with threadpool_limits(limits=1, user_api="blas"):
        return _barrier(program, c0, tolerance, t0)


def _barrier(program: DiscProgram, c0, tolerance: float, t0) -> np.ndarray:
    P, q = program.P, program.q
    n = q.size
    c = np.zeros(n) if c0 is None else np.asarray(c0, dtype=float).copy()
    if np.any(program.slack(c) <= 0.0):
        raise ValueError("the barrier method needs a start strictly inside every disc")
    Vr, Vi = np.ascontiguousarray(program.rows.real), np.ascontiguousarray(program.rows.imag)
    m = program.radii.size
    if m == 0:
        return np.linalg.lstsq(P, -q, rcond=None)[0]
    scale = max(abs(program.objective(c)), 1.0)
    t = m / scale if t0 is None else t0

    def value(v, weight):
        s = program.slack(v)
        return np.inf if np.any(s <= 0.0) else weight * program.objective(v) - float(np.sum(np.log(s)))

    while True:
        for _ in range(_NEWTON_STEPS):
            r = program.offsets + program.rows @ c
            s = program.radii**2 - (r.real**2 + r.imag**2)
            gradient = t * 2.0 * (P @ c + q) + 2.0 * (Vr.T @ (r.real / s) + Vi.T @ (r.imag / s))
            # The barrier's Hessian: sum_k (2 / s_k) R_k'R_k + (4 / s_k^2) R_k'r_k r_k'R_k, R_k = [Re v_k; Im v_k].
            W = (r.real / s)[:, None] * Vr + (r.imag / s)[:, None] * Vi
            inverse = 1.0 / s
            hessian = 2.0 * t * P + 2.0 * ((Vr.T * inverse) @ Vr + (Vi.T * inverse) @ Vi) + 4.0 * (W.T @ W)
            # Near the optimum the barrier's curvature spans many decades (1 / s^2 of the discs that bind
            # against 2 t P elsewhere): Cholesky still gives the Newton step; only a matrix that is not
            # numerically positive definite falls back to least squares.
            try:
                step = -scipy.linalg.cho_solve(scipy.linalg.cho_factor(hessian), gradient)
            except (np.linalg.LinAlgError, scipy.linalg.LinAlgError):
                step = -np.linalg.lstsq(hessian, gradient, rcond=None)[0]
            decrement = float(-gradient @ step)
            # Newton's decrement against the objective's scale: t J - sum log s grows with t, and an
            # absolute tolerance would lie below its round-off in the last rounds.
            if decrement / 2.0 <= _CENTRING * t * scale:
                break
            start = value(c, t)
            size = 1.0
            while size > 1e-14 and value(c + size * step, t) > start - _ALPHA * size * decrement:
                size *= _BETA
            if size <= 1e-14:
                break
            c = c + size * step
        if m / t <= tolerance * scale:
            return c
        t *= MU
