"""Output-error refinement of a model against the raw DFT of the noise recording.

The seed's pipeline fits smoothed FRF samples, and smoothing is biased at lightly
damped modes (design.md, identification step 5). This step fits the raw data
instead. For one block of L samples with DFTs U_k, Y_k at z_k = e^{j 2 pi k / L}
the state equation gives exactly (McKelvey, "Frequency domain identification
methods", Circuits Systems Signal Process. 21(1), 2002, eq. 7)

    Y_k = [C (z_k I - A)^-1 B + D] z_k^-d U_k + C (z_k I - A)^-1 z_k x_delta + V_k,

where x_delta = x(0) - x(L) is the block's transient and V_k the output noise. With
A in real block-diagonal (modal) form and C = [1 0 | 1 0 | 1 ...], everything but
the poles enters linearly (B, D, x_delta), so the poles are found by variable
projection (Golub & Pereyra 1973): minimise over the poles the residual of the
linear least-squares problem in the rest,

    V(poles) = min_{B, D, x_delta} sum_k |Y_k - model_k|^2,

the maximum-likelihood criterion for white output noise. Poles are parametrised so
that every iterate is stable and no slower than the block can resolve: a complex pair as
r e^{+-j theta} with r = exp(-exp(sigma) - 1/L), a real pole as exp(-1/L) tanh(xi), L the
block's length (``decay_bound``).

The step's parts: the block's DFT bins (``sysid.estimation.output_error_data``), the
modal parametrisation, its basis and the decay bound
(``sysid.estimation.modal_parametrisation``) and the linear least squares solved at every
evaluation (``sysid.estimation.least_squares``). Here: the criterion and its Jacobian, the
Levenberg-Marquardt driver ``refine_output_error``, and the costs with the poles held
fixed (``linear_cost``, ``added_pole_costs``, ``residual_spectrum``). ``BlockData``,
``block_data``, ``modal_basis``, ``decay_bound``, ``radius_bound_mask``,
``at_radius_bound`` and ``split_near_real_pairs`` are importable from here as well.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
from threadpoolctl import ThreadpoolController

from ..core import lti
from ..core.errors import IdentificationError
from .least_squares import qr_solve
from .modal_parametrisation import (at_radius_bound, decay_bound, modal_basis, params_to_poles, pole_derivatives,
                                    poles_to_params, radius_bound_mask, split_near_real_pairs)
from .output_error_data import BlockData, block_data

# BLAS libraries found once at import (numpy's and scipy's are loaded by then); limiting
# through it costs microseconds, threadpool_limits() rescans the process's libraries (4 ms).
_BLAS = ThreadpoolController()

__all__ = ["BlockData", "block_data", "OutputErrorFit", "refine_output_error", "modal_basis", "linear_cost",
           "residual_spectrum", "added_pole_costs", "decay_bound", "at_radius_bound", "radius_bound_mask",
           "split_near_real_pairs"]

# Imported from here by the names they had before the parametrisation had a module of its own
# (sysid.estimation.uncertainty); modal_parametrisation holds them.
_poles_to_params, _params_to_poles = poles_to_params, params_to_poles


@dataclass
class OutputErrorFit:
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    cost_before: float
    cost_after: float
    iterations: int


def _stacked_real(basis: np.ndarray, factors: list[np.ndarray],
                  extra: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """[Re; Im] of the complex regressor [basis * f_1, basis * f_2, ..., extra] (each factor f a
    vector over the bins scaling every basis column; ``extra`` one more column), columns scaled to
    unit norm, and the scales.

    Built in place, column-major (Fortran order), as LAPACK's QR takes it: a row-major copy costs
    the QR of a 100000 x 36 block a third of its time. Column scaling keeps the solve well
    conditioned when modes differ by decades.
    """
    m, n = basis.shape
    real = np.empty((2 * m, n * len(factors) + (extra is not None)), order="F")
    block = np.empty((m, n), dtype=complex, order="F")
    for k, f in enumerate(factors):
        np.multiply(basis, f[:, None], out=block)
        real[:m, k * n:(k + 1) * n], real[m:, k * n:(k + 1) * n] = block.real, block.imag
    if extra is not None:
        real[:m, -1], real[m:, -1] = extra.real, extra.imag
    scale = np.sqrt(np.einsum("ij,ij->j", real, real))
    scale[scale == 0] = 1.0
    real /= scale
    return real, scale


class _Problem:
    def __init__(self, data: BlockData, delay: int, feedthrough: bool, prefilter: np.ndarray | None = None):
        self.data, self.feedthrough = data, feedthrough
        self.u_delayed = data.U * data.z ** (-delay)
        self.weight = np.ones(data.z.size) if prefilter is None else np.asarray(prefilter, dtype=complex)
        self.u_delayed = self.u_delayed * self.weight
        self.rhs = np.concatenate([data.Y.real, data.Y.imag])

    def regression(self, poles):
        """(A, C, regressor, scales, rhs) for the poles: the modal (A, C), the [Re; Im] regressor of the
        input and transient columns (then D) with unit-norm columns (``_stacked_real``), their
        scales, and [Re; Im] of Y."""
        A = lti.real_block_diagonal(poles)
        C = lti.block_output_row(A)
        basis = modal_basis(A, C, self.data.z)
        real, scale = _stacked_real(basis, [self.u_delayed, self.data.z], self.u_delayed if self.feedthrough else None)
        return A, C, real, scale, self.rhs

    def linear(self, poles):
        A, C, real, scale, rhs = self.regression(poles)
        scaled = qr_solve(real, rhs)[1]
        return A, C, scaled / scale, rhs - real @ scaled


class _Projection:
    """Residual and Jacobian of the variable-projection criterion (Golub & Pereyra 1973).

    With the regressor Phi(poles) and theta(poles) its least-squares solution, the
    residual is r = y - Phi theta. Kaufman's approximation of its Jacobian (Kaufman,
    BIT 15, 1975, eq. 2.5) is J_j = -P (dPhi / dx_j) theta with P = I - Q Q^T the
    projector off the range of Phi (Q from a QR factorisation). A parameter moves only
    the pole p of its own block, so dPhi/dx_j theta is the derivative of that block's columns
    times their coefficients, in closed form: with g = 1/(z - p) and h = 1/(z - conj p) a
    pair's columns are (g + h)/2 and (g - h)/2j, a real pole's is g, and dg/dx = g^2 dp/dx.
    One QR per iteration instead of one least-squares solve per parameter.
    ``margin`` is the block's ``decay_bound``.
    """

    def __init__(self, problem: _Problem, pairs: int, full: bool = True):
        self.problem, self.pairs, self._full = problem, pairs, full
        self.margin = decay_bound(problem.data)
        self._x, self._previous = None, None
        self._jacobian_at = None

    _STATE = ("_x", "_poles", "_factor", "_scale", "_theta", "_residual")

    def _solve(self, x):
        """The linear least squares at x, kept for the last two points: MINPACK's result is its last
        accepted point, often followed by a rejected trial, and ``linear`` asks for it again."""
        if self._x is not None and np.array_equal(x, self._x):
            return
        if self._previous is not None and np.array_equal(x, self._previous[0]):
            current = tuple(getattr(self, name) for name in self._STATE)
            for name, value in zip(self._STATE, self._previous):
                setattr(self, name, value)
            self._previous = current
            return
        if self._x is not None:
            self._previous = tuple(getattr(self, name) for name in self._STATE)
        poles = params_to_poles(x, self.pairs, self.margin)
        _, _, real, scale, rhs = self.problem.regression(poles)
        factor, scaled = qr_solve(real, rhs)
        self._x, self._poles, self._factor, self._scale, self._theta = x.copy(), poles, factor, scale, scaled / scale
        self._residual = rhs - real @ scaled

    def residual(self, x):
        """The residual at x (a copy: MINPACK may write into the array it is given).

        A trial point that is not finite (MINPACK's step computation broke down in its own arithmetic:
        random helmet 100 FB with a time-varying plant, an order-14 fit of the order search proposed all-NaN
        parameters from a finite residual and Jacobian) gets a residual far above the last one, which MINPACK
        rejects: it keeps its last accepted point and stops at its evaluation limit, instead of handing the
        least squares a NaN regressor."""
        if not np.all(np.isfinite(x)):
            return np.full_like(self._residual, 1e6 * max(float(np.max(np.abs(self._residual))), 1.0))
        self._solve(x)
        return self._residual.copy()

    def linear(self, x):
        """(A, C, theta, residual) at x as ``_Problem.linear`` of its poles, from the last evaluation when
        it was at x (MINPACK's last evaluation is usually its result)."""
        self._solve(x)
        A = lti.real_block_diagonal(self._poles)
        return A, lti.block_output_row(A), self._theta, self._residual

    def jacobian(self, x):
        """The Jacobian at x; the first one is kept, and a call at its point again returns it (``leastsq``
        checks the Jacobian's shape at the start point, where MINPACK then asks for it again). Every array
        returned is the caller's: MINPACK factors the Jacobian in place."""
        if self._jacobian_at is not None and np.array_equal(x, self._jacobian_at[0]):
            return self._jacobian_at[1].copy()
        jac = self._jacobian(x)
        if self._jacobian_at is None:
            self._jacobian_at = (x.copy(), jac.copy())
        return jac

    def _jacobian(self, x):
        self._solve(x)
        p, theta, n, pairs = self.problem, self._theta, self._poles.size, self.pairs
        z, u = p.data.z, p.u_delayed
        m = z.size
        # Every parameter moves the pole of its own block only: the closed-form derivatives of the
        # block bases, all parameters at once (columns), then one projection.
        count = x.size
        j = np.arange(count)
        # First state of each parameter's block (the pairs' blocks first, then the real poles).
        state = np.where(j < 2 * pairs, 2 * (j // 2), j)
        is_pair = j < 2 * pairs
        pc, rc = np.flatnonzero(is_pair), np.flatnonzero(~is_pair)
        dp = pole_derivatives(x, pairs, self.margin)
        upper = self._poles[:pairs]
        reals = self._poles[2 * pairs:].real
        # Coefficients of each block's columns: a pair's first column (g + h)/2 carries
        # theta_s u + theta_{n+s} z, its second (g - h)/2j carries theta_{s+1} u + theta_{n+s+1} z;
        # so dPhi theta = dp g^2 alpha + conj(dp) h^2 beta with alpha = (a - j b)/2, beta = (a + j b)/2.
        # One row per pair (or real pole) and one column per bin: every row contiguous, and the
        # derivative columns below copy row by row into the column-major Jacobian.
        # The pairs' element-wise passes write into arrays already allocated (out=), j b is formed once, each
        # operation on the same operands in the same order as the plain expressions, so the same last bits
        # (numpy's complex product is not symmetric in its last bit: operand order is kept); 4 % of the
        # Jacobian's CPU on a 1 s block at n 23.
        s0 = 2 * np.arange(pairs)
        zr, ur = z[None, :], u[None, :]
        a = _linear_in_theta(ur, zr, theta[s0, None], theta[n + s0, None])
        b = _linear_in_theta(ur, zr, theta[s0 + 1, None], theta[n + s0 + 1, None])
        g2 = _inverse_square(zr, upper[:, None])
        h2 = _inverse_square(zr, np.conj(upper)[:, None])
        jb = np.multiply(1j, b, out=b)
        g_alpha = np.multiply(0.5, g2)
        np.multiply(g_alpha, np.subtract(a, jb), out=g_alpha)
        h_beta = np.multiply(0.5, h2)
        np.multiply(h_beta, np.add(a, jb, out=a), out=h_beta)
        g_real = _inverse_square(zr, reals[:, None])
        dv = np.empty((count, m), dtype=complex)
        block = pc // 2
        # A pair's two parameters (pc = 0 .. 2 pairs - 1, the first rows) share its block: broadcast, not
        # gathered, and written in place.
        both = dp[pc].reshape(pairs, 2, 1)
        pair_rows = dv[:2 * pairs].reshape(pairs, 2, m)
        np.multiply(g_alpha[:, None, :], both, out=pair_rows)
        pair_rows += h_beta[:, None, :] * np.conj(both)
        # Not in place: a product written over its own broadcast operand took another loop of numpy's and
        # moved the last bits (random helmet 4, short session: order 20 for 16).
        dv[rc] = g_real * (dp[rc, None] * (ur * theta[rc, None] + zr * theta[n + rc, None]))
        columns = np.empty((2 * m, count), order="F")
        columns[:m], columns[m:] = dv.real.T, dv.imag.T
        # J = -(I - Q Q^T) dPhi theta [- Q R^-T g]: one product with Q for both terms.
        back = self._factor.qt(columns)
        if self._full:
            # Second Golub-Pereyra term -(Phi^+)^T dPhi^T r, Phi^+ = R^-1 Q^T for the scaled columns:
            # the derivative of column c times r, for the u and the z columns of each block.
            r = self._residual[:m] + 1j * self._residual[m:]
            weights = np.stack([u * np.conj(r), z * np.conj(r)], axis=1)
            g = np.zeros((self._factor.columns, count))
            gw, hw = g2 @ weights, h2 @ weights
            # d(first)/dx = (dp g^2 + conj(dp) h^2)/2, d(second)/dx = (dp g^2 - conj(dp) h^2)/2j.
            d_first = 0.5 * (dp[pc, None] * gw[block] + np.conj(dp[pc])[:, None] * hw[block])
            d_second = -0.5j * (dp[pc, None] * gw[block] - np.conj(dp[pc])[:, None] * hw[block])
            d_real = dp[rc, None] * (g_real @ weights)
            ps = state[pc]
            for offset, d in ((0, d_first), (1, d_second)):
                g[ps + offset, pc] = d[:, 0].real / self._scale[ps + offset]
                g[n + ps + offset, pc] = d[:, 1].real / self._scale[n + ps + offset]
            g[rc, rc] = d_real[:, 0].real / self._scale[rc]
            g[n + rc, rc] = d_real[:, 1].real / self._scale[n + rc]
            back -= self._factor.pinv_t(g)
        jac = self._factor.q_times(back) - columns
        return jac


def _linear_in_theta(u: np.ndarray, z: np.ndarray, on_u: np.ndarray, on_z: np.ndarray) -> np.ndarray:
    """u on_u + z on_z (rows of coefficients times the bins' input and z), in one array."""
    out = np.multiply(u, on_u)
    out += z * on_z
    return out


def _inverse_square(z: np.ndarray, poles: np.ndarray) -> np.ndarray:
    """(1 / (z - p))^2, one row per pole, in one array."""
    out = np.subtract(z, poles)
    np.divide(1.0, out, out=out)
    return np.square(out, out=out)


def refine_output_error(A, B, C, D, data: BlockData, delay: int = 0, feedthrough: bool = False,
                        max_iterations: int = 60, prefilter: np.ndarray | None = None,
                        noise_tolerance: bool = False, split_near_real: bool = False) -> OutputErrorFit:
    """Refine a stable model's poles and zeros on raw DFT data; see the module docstring.

    The returned model is balanced (``lti.balanced_realisation``).

    ``noise_tolerance`` stops the iterations once one lowers the cost by less than 1/N of
    it (N real residuals, 2 per bin): less than one output-noise variance sigma^2 = V / N,
    less than a parameter fitted to noise alone gains, so statistically nothing (MINPACK's
    ftol; otherwise 1e-8). On the final 10 s block of random helmet 5 (thesis-length session,
    order 17) the cost fell 0.29 % in 10 iterations, then 4e-6 more in 50 (18 s of CPU),
    the validation rms 1.016x the floor throughout.

    ``split_near_real`` refines every nearly real pair of the start as two real poles
    (``split_near_real_pairs``).

    ``prefilter`` (complex response at the data's bins) is a fixed factor F in series
    in front of the fitted system: the fit is of Y = G F z^-d U, and the returned
    (A, B, C, D) is G alone.
    """
    poles = np.linalg.eigvals(np.asarray(A, dtype=float))
    if poles.size == 0:
        raise IdentificationError("output-error refinement needs a model of order at least 1")
    if np.max(np.abs(poles)) >= 1:
        raise IdentificationError("output-error refinement needs a stable starting model")
    problem = _Problem(data, delay, feedthrough, prefilter)
    margin = decay_bound(data)
    params, pairs = poles_to_params(split_near_real_pairs(poles, margin) if split_near_real else poles, margin)
    projection = _Projection(problem, pairs)

    # MINPACK's lmder (Levenberg-Marquardt, scaled by the Jacobian's column norms) through ``leastsq``, as
    # least_squares' "lm" calls it, but without the Jacobian least_squares evaluates again at the result
    # (one more per refinement: 48 ms on a 10 s block at n 21). maxfev counts residual evaluations.
    with _BLAS.limit(limits=1, user_api="blas"):
        start = projection.residual(params)
        solution, _, info, _, _ = scipy.optimize.leastsq(
            projection.residual, params, Dfun=projection.jacobian, full_output=True, maxfev=max_iterations,
            ftol=1.0 / start.size if noise_tolerance else 1e-8, xtol=1e-8, gtol=1e-8)
    # r = exp(-exp(sigma)) rounds to 1 in floating point when sigma runs far negative: such a
    # result is not stable and the starting poles are kept instead.
    stable = np.all(np.abs(params_to_poles(solution, pairs, margin)) < 1.0)
    x = solution if stable and np.sum(info["fvec"]**2) <= np.sum(start**2) else params
    with _BLAS.limit(limits=1, user_api="blas"):
        A_new, C_new, theta, final = projection.linear(x)
    n = A_new.shape[0]
    B_new = theta[:n].reshape(n, 1)
    D_new = np.array([[theta[2 * n] if feedthrough else 0.0]])
    # The modal form with a unit output row puts every gain into B (1e9-1e12 for nearly
    # coincident poles); the model leaves here balanced, every entry of order one.
    A_new, B_new, C_new, D_new = lti.balanced_realisation(A_new, B_new, C_new, D_new)
    return OutputErrorFit(A_new, B_new, C_new, D_new, float(np.sum(start**2)), float(np.sum(final**2)), int(info["nfev"]))


def linear_cost(A, data: BlockData, delay: int = 0, feedthrough: bool = False,
                prefilter: np.ndarray | None = None) -> float:
    """Output-error cost sum_k |Y_k - model_k|^2 with the poles of A held fixed.

    Only the linear least-squares step of the variable projection: cheap enough to
    scan a structure parameter (a delay, a corner frequency) before refining.
    """
    poles = np.linalg.eigvals(np.asarray(A, dtype=float))
    with _BLAS.limit(limits=1, user_api="blas"):
        residual = _Problem(data, delay, feedthrough, prefilter).linear(poles)[3]
    return float(np.sum(residual**2))


def added_pole_costs(A, added: list[np.ndarray], data: BlockData, feedthrough: bool = False) -> np.ndarray:
    """``linear_cost`` of the poles of A joined by each pole set of ``added`` (each closed under
    conjugation), for many sets at the cost of one QR.

    The cost is the squared distance of Y from the span of the regressor's columns, and the modal
    columns of A's blocks are the same whatever block is added; so A's columns are factored once
    (Q), each added block's columns are projected off them (twice, classical Gram-Schmidt with
    reorthogonalisation) and the base residual's least-squares drop onto what is left is
    subtracted: per set, products with Q and a solve of four columns instead of a QR of all 2n + 4.
    """
    poles = np.linalg.eigvals(np.asarray(A, dtype=float))
    problem = _Problem(data, 0, feedthrough)
    costs = []
    with _BLAS.limit(limits=1, user_api="blas"):
        _, _, real, _, rhs = problem.regression(poles)
        factor, scaled = qr_solve(real, rhs)
        residual = rhs - real @ scaled
        # Chunks of sets bound the memory of the stacked columns on long blocks.
        for start in range(0, len(added), 16):
            chunk = added[start:start + 16]
            blocks = []
            for extra in chunk:
                block = lti.real_block_diagonal(np.asarray(extra))
                blocks.append(_stacked_real(modal_basis(block, lti.block_output_row(block), data.z),
                                            [problem.u_delayed, data.z])[0])
            columns = np.hstack(blocks)
            for _ in range(2):
                columns -= factor.q_times(factor.qt(columns))
            at = 0
            for block in blocks:
                w = columns[:, at:at + block.shape[1]]
                at += block.shape[1]
                # The columns had unit norm before the projection: what is left below 1e-10 of it lies in
                # A's span (an added pole repeating one of A's) and adds nothing, as the minimum-norm solve.
                u, singular, _ = np.linalg.svd(w, full_matrices=False)
                along = u[:, singular > 1e-10].T @ residual
                costs.append(float(residual @ residual - along @ along))
    return np.array(costs)


def residual_spectrum(A, data: BlockData, delay: int = 0, feedthrough: bool = False) -> np.ndarray:
    """Complex output-error residual Y_k - model_k at the block's bins, poles of A held fixed."""
    poles = np.linalg.eigvals(np.asarray(A, dtype=float))
    residual = _Problem(data, delay, feedthrough).linear(poles)[3]
    m = data.z.size
    return residual[:m] + 1j * residual[m:]
