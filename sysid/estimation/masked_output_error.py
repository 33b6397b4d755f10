"""Output-error refinement in the time domain over the kept samples of a recording with gaps.

A recording whose ear signal is missing in stretches (clipped: a model's ``excluded``,
``sysid.io.corrections``) still has its whole input. The core's prediction is the response
of its states to the whole input, and only the kept samples enter the cost:

    V(theta) = sum over kept t of (y_t - c^T x_t(theta) - d v_t)^2,

x_t(theta) the states of the real block-diagonal core with poles theta driven by v from
rest (a real pole p: x(t+1) = p x(t) + v(t); a pair sigma +- j omega: the 2x2 block
[[sigma, omega], [-omega, sigma]] with input row [1, 0]). Given the poles the prediction is
linear in (c, d): those by least squares over the kept samples; the poles by
Levenberg-Marquardt on the projected residual (variable projection: Golub & Pereyra,
SIAM J. Numer. Anal. 10(2), 1973; the Jacobian of Kaufman, BIT 15, 1975:
J_k = -P_perp (dX / dtheta_k) c, P_perp the projector off the columns of X on the kept
samples). Excluded samples are dropped from the cost, not filled with a prediction: a fill
by the model being fitted pulls the fit towards itself (EM converges at the rate of the
missing information, slowly when the gaps hold most of the recording's loud samples).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.signal
from threadpoolctl import threadpool_limits

from .output_error import OutputErrorFit

__all__ = ["refine_masked", "refine_masked_inputs"]

# Largest pole radius a step may reach: a pole on the unit circle is no stable core.
_RADIUS_BOUND = 1.0 - 1e-9
# Finite-difference step of a pole parameter, relative to its distance 1 - |p| from the unit circle
# (a pole at 0.9997 moves its state's gain 1 / (1 - p) by 1e-4 of itself).
_STEP = 1e-4


def _blocks(poles: np.ndarray) -> tuple[list[int], np.ndarray]:
    """(sizes of the blocks, 1 real or 2 pair; their parameters: p, or sigma and omega) of conjugate-closed poles."""
    poles = np.asarray(poles, dtype=complex)
    sizes, theta = [], []
    for p in poles[np.argsort(-np.abs(poles))]:
        if abs(p.imag) <= 1e-12 * max(1.0, abs(p)):
            sizes.append(1)
            theta.append(p.real)
        elif p.imag > 0:
            sizes.append(2)
            theta += [p.real, p.imag]
    return sizes, np.array(theta, dtype=float)


def _block_states(size: int, theta: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The states (columns) of one block driven by v from rest; see the module docstring. A v of several
    columns (inputs) gives the block's states for each in turn."""
    if v.ndim == 2:
        return np.concatenate([_block_states(size, theta, column) for column in v.T], axis=1)
    if size == 1:
        return scipy.signal.sosfilt([[0.0, 1.0, 0.0, 1.0, -theta[0], 0.0]], v)[:, None]
    sigma, omega = theta
    den = [1.0, -2.0 * sigma, sigma**2 + omega**2]
    # (zI - A)^-1 [1, 0]^T = [z - sigma, -omega] / ((z - sigma)^2 + omega^2).
    return np.stack([scipy.signal.sosfilt([[0.0, 1.0, -sigma, *den]], v),
                     scipy.signal.sosfilt([[0.0, 0.0, -omega, *den]], v)], axis=1)


def _radius(size: int, theta: np.ndarray) -> float:
    return abs(theta[0]) if size == 1 else float(np.hypot(*theta))


def _split(sizes: list[int], theta: np.ndarray) -> list[np.ndarray]:
    return np.split(theta, np.cumsum(sizes)[:-1])


def refine_masked(A, v: np.ndarray, y: np.ndarray, keep: np.ndarray, feedthrough: bool = False,
                  max_iterations: int = 20) -> OutputErrorFit:
    """The core with the poles of A refined by output error over the ``keep`` samples of (v, y); see the
    module docstring. v: the core's input (FS) from the recording's first sample (the states start at
    rest there), y: the ear signal the core should predict (FS), keep: True where y counts. Stops when
    an accepted step lowers the cost by less than P / N of itself (P parameters, N kept samples: what
    fitting the noise alone would gain, the noise tolerance of ``output_error``)."""
    # Tall thin least squares: BLAS threads only add overhead (as in ``identify``).
    with threadpool_limits(limits=1, user_api="blas"):
        return _refine_masked(A, v, y, keep, feedthrough, max_iterations)


def refine_masked_inputs(A, V: np.ndarray, y: np.ndarray, keep: np.ndarray, feedthrough: bool = False,
                         max_iterations: int = 20):
    """(A, B, C, D) of the common poles refined over the ``keep`` samples for several inputs (the columns of
    V, each with its own numerator: C has a row per input, D an entry per input; A block-diagonal, B the
    unit input rows), as ``refine_masked`` does for one. A Hammerstein model's powers u, u^2, ... through one
    core is this with rank-one numerators; fitted free, the poles need no map to start from (the
    over-parametrised relaxation of Bai, Automatica 34(3), 1998, sec. 3)."""
    V = np.asarray(V, float)
    with threadpool_limits(limits=1, user_api="blas"):
        sizes, theta, c, _ = _refine_masked(A, V if V.ndim == 2 else V[:, None], y, keep, feedthrough,
                                            max_iterations, full=True)
    inputs = V.shape[1] if V.ndim == 2 else 1
    A_out, B_out = _realised(sizes, theta)
    n = A_out.shape[0]
    C_out, k = np.zeros((inputs, n)), 0
    position = 0
    for size in sizes:
        for j in range(inputs):
            C_out[j, k:k + size] = c[position:position + size]
            position += size
        k += size
    D_out = c[position:position + inputs] if feedthrough else np.zeros(inputs)
    return A_out, B_out, C_out, D_out


def _realised(sizes, theta):
    """(A, B) of the real block-diagonal form of the pole parameters (the module docstring's)."""
    n = sum(sizes)
    A_out, B_out = np.zeros((n, n)), np.zeros((n, 1))
    k = 0
    for size, block in zip(sizes, _split(sizes, theta)):
        if size == 1:
            A_out[k, k] = block[0]
        else:
            sigma, omega = block
            A_out[k:k + 2, k:k + 2] = [[sigma, omega], [-omega, sigma]]
        B_out[k, 0] = 1.0
        k += size
    return A_out, B_out


def _refine_masked(A, v, y, keep, feedthrough, max_iterations, full: bool = False):
    v, y, keep = np.asarray(v, float), np.asarray(y, float), np.asarray(keep, bool)
    inputs = v.shape[1] if v.ndim == 2 else 1
    sizes, theta = _blocks(np.linalg.eigvals(np.asarray(A, float)))
    y_kept = y[keep]
    tolerance = (theta.size + inputs * (sum(sizes) + int(feedthrough))) / max(int(np.count_nonzero(keep)), 1)

    def evaluate(theta):
        states = [_block_states(s, t, v) for s, t in zip(sizes, _split(sizes, theta))]
        X = np.concatenate(states + ([v if v.ndim == 2 else v[:, None]] if feedthrough else []), axis=1)[keep]
        Q, R = scipy.linalg.qr(X, mode="economic", overwrite_a=True, check_finite=False)
        c = np.linalg.lstsq(R, Q.T @ y_kept, rcond=None)[0]
        residual = y_kept - X @ c
        return float(residual @ residual), residual, c, Q, states

    def jacobian(theta, c, Q, states):
        columns, k, start = [], 0, 0
        for size, block, base in zip(sizes, _split(sizes, theta), states):
            for j in range(block.size):
                h = _STEP * max(1.0 - _radius(size, block), 1e-6)
                moved = block.copy()
                moved[j] += h
                change = ((_block_states(size, moved, v) - base) / h)[keep] @ c[start:start + size * inputs]
                columns.append(-(change - Q @ (Q.T @ change)))
                k += 1
            start += size * inputs
        return np.stack(columns, axis=1)

    cost, residual, c, Q, states = evaluate(theta)
    cost_before, damping, iterations = cost, 1e-3, 0
    for iterations in range(1, max_iterations + 1):
        J = jacobian(theta, c, Q, states)
        H, g = J.T @ J, J.T @ residual
        scale = np.maximum(np.diag(H), 1e-300)
        improved = False
        while damping < 1e10:
            step = np.linalg.solve(H + damping * np.diag(scale), -g)
            trial = theta + step
            if all(_radius(s, t) < _RADIUS_BOUND for s, t in zip(sizes, _split(sizes, trial))):
                result = evaluate(trial)
                if result[0] < cost:
                    gain = (cost - result[0]) / cost
                    theta, (cost, residual, c, Q, states) = trial, result
                    damping = max(damping / 10.0, 1e-9)
                    improved = True
                    break
            damping *= 10.0
        if not improved or gain < tolerance:
            break
    if full:
        return sizes, theta, c, (cost_before, cost, iterations)
    A_out, B_out = _realised(sizes, theta)
    n = sum(sizes)
    C_out = c[:n][None, :]
    D_out = np.array([[c[n] if feedthrough else 0.0]])
    return OutputErrorFit(A_out, B_out, C_out, D_out, cost_before, cost, iterations)
