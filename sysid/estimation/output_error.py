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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize
from scipy.linalg import blas, lapack
from threadpoolctl import ThreadpoolController

from ..core import lti
from ..core.errors import IdentificationError
from ..core.thresholds import IDENTIFICATION_BAND
from ..io.recordings import Recording
from ..validation.sweeps import rfft_pair

# BLAS libraries found once at import (numpy's and scipy's are loaded by then); limiting
# through it costs microseconds, threadpool_limits() rescans the process's libraries (4 ms).
_BLAS = ThreadpoolController()

__all__ = ["BlockData", "block_data", "OutputErrorFit", "refine_output_error", "modal_basis", "linear_cost",
           "residual_spectrum", "added_pole_costs", "decay_bound", "at_radius_bound", "radius_bound_mask"]


@dataclass
class BlockData:
    """DFT bins of one data block inside the band: z_k, U_k, Y_k, and the block length."""

    z: np.ndarray
    U: np.ndarray
    Y: np.ndarray
    length: int
    fs: float


def block_data(noise: Recording, band=IDENTIFICATION_BAND, max_seconds: float | None = 10.0) -> BlockData:
    """The band's DFT bins of (at most max_seconds of) a noise recording after its transient."""
    n = noise.u.size if max_seconds is None else min(noise.u.size, int(round(max_seconds * noise.fs)))
    if n < 16:
        raise IdentificationError(f"{noise.path}: too short for output-error refinement")
    f = np.fft.rfftfreq(n, 1 / noise.fs)
    inside = (f >= band[0]) & (f <= band[1])
    u = noise.u[:n] - noise.u[:n].mean()
    y = noise.y[:n] - noise.y[:n].mean()
    U, Y = rfft_pair(u, y)
    return BlockData(np.exp(2j * np.pi * f[inside] / noise.fs), U[inside], Y[inside], n, noise.fs)


def modal_basis(A_block: np.ndarray, C: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Columns C (zI - A)^-1 e_j for a real block-diagonal A (M x n), in closed form per block.

    Column-major, each column written contiguously."""
    n = A_block.shape[0]
    basis = np.empty((z.size, n), dtype=complex, order="F")
    i = 0
    while i < n:
        if i + 1 < n and A_block[i, i + 1] != 0:
            a, b = A_block[i, i], A_block[i, i + 1]
            # (zI - [[a, b], [-b, a]])^-1 = [[z - a, b], [-b, z - a]] / ((z - a)^2 + b^2)
            # Each quotient written straight into its column, the numerators into one scratch array
            # (the same operations and operand order as the plain expressions: the same bits).
            shifted = z - a
            den = np.square(shifted)
            den += b**2
            c0, c1 = C[0, i], C[0, i + 1]
            numerator = np.multiply(c0, shifted)
            numerator -= c1 * b
            np.divide(numerator, den, out=basis[:, i])
            np.multiply(c1, shifted, out=numerator)
            np.add(c0 * b, numerator, out=numerator)
            np.divide(numerator, den, out=basis[:, i + 1])
            i += 2
        else:
            shifted = z - A_block[i, i]
            np.divide(C[0, i], shifted, out=basis[:, i])
            i += 1
    return basis


# A pole counts as at the radius bound when its decay rate -ln|p| is within this fraction above
# the bound's (``at_radius_bound``).
_AT_BOUND = 0.01
# Decay bound without a block: stability alone (|p| <= 1 - 1e-9).
_STABLE = 1e-9
# A pair whose angle is below this fraction of its decay rate is refined as two real poles
# (``split_near_real_pairs``), of decay rates this fraction above and below the pair's.
_NEAR_REAL = 1e-3
_NEAR_REAL_SPLIT = 0.1
# Largest condition number of a regressor solved through its Gram matrix (``_Factor``).
_GRAM_CONDITION = 1e5
# Distance (relative to the unit column norm) from the span of the other columns below which a column is
# tried as dependent (``_Factor``): Gram-matrix pivoting resolves distances down to about sqrt(eps).
_DEPENDENT_DISTANCE = 1e-6
_UNIT_ROUNDOFF = np.finfo(float).eps / 2


def decay_bound(data: "BlockData") -> float:
    """Smallest decay rate -ln|p| (per sample) of a pole refined on the block: 1/L, L its length.

    A pole whose time constant -1/ln|p| is longer than the block's L samples cannot be told
    from the block's transient term (the x_delta columns): the data do not resolve it. Before
    this bound (|p| <= 1 - 1e-9) spare poles ran to z = 1 or z = -1 out of the fitted band,
    invisible in the sweeps' spectra but ringing in the simulated sweeps (random helmet 41, short
    session: a pair at 23944 Hz and a real pole at z = -1 with large residues cancelling in band,
    70000x the floor in simulation) and in a controller built on the model. Lightly damped
    in-band modes stay reachable: Q 50 at 30 Hz and 48 kHz is 1 - |p| = pi 30 / (50 48000) =
    3.9e-5, above 1/L = 2.1e-5 for a 1 s block (2.1e-6 for 10 s). A tighter bound out of the band
    (the decay of a Q 50 mode at the pole's distance from it) put two random helmets above the floor
    (thesis-length 13: 1.21x, short 1: 1.41x, both at the floor with 1/L alone) and is not used.
    """
    return 1.0 / data.length


def radius_bound_mask(poles: np.ndarray, data: "BlockData") -> np.ndarray:
    """Which of ``poles`` sit at the block's ``decay_bound`` (decay -ln|p| within 1 % of it): poles
    the block could not hold, run out to the limit of the parametrisation."""
    decay = -np.log(np.maximum(np.abs(np.asarray(poles)), 1e-300))
    return decay <= (1 + _AT_BOUND) * decay_bound(data)


def at_radius_bound(poles: np.ndarray, data: "BlockData") -> bool:
    """Whether any of ``poles`` sits at the block's ``decay_bound`` (``radius_bound_mask``)."""
    return bool(np.any(radius_bound_mask(poles, data)))


def _poles_to_params(poles: np.ndarray, margin: float = _STABLE) -> tuple[np.ndarray, int]:
    """Parameter vector (sigma, theta per upper-half-plane pair, then xi per real pole) under the
    decay bound ``margin`` (-ln of the largest radius; ``decay_bound``); poles beyond it start inside it."""
    pairs = [p for p in poles if p.imag > 1e-12]
    reals = [p.real for p in poles if abs(p.imag) <= 1e-12]
    params = []
    for p in pairs:
        r = min(abs(p), 1 - 1e-12)
        # A start at or beyond the bound begins a tenth of the bound's decay inside it, where sigma still moves it.
        params += [np.log(max(-np.log(r) - margin, 0.1 * margin)), np.angle(p)]
    params += [np.arctanh(np.clip(p / np.exp(-margin), -1 + 1e-12, 1 - 1e-12)) for p in reals]
    return np.array(params, dtype=float), len(pairs)


def split_near_real_pairs(poles: np.ndarray, margin: float = _STABLE) -> np.ndarray:
    """The poles with every nearly real pair replaced by two real poles of nearby decay rates.

    A pair r e^{+-j theta} whose angle theta is below _NEAR_REAL times its decay rate d = -ln r is a
    double real pole in all but name; the cost is even in theta there, so its theta column of the
    Jacobian vanishes (2.3e-7 of the largest on random helmet 17's final 10 s block, theta = 1.1e-7,
    d = 0.015), the scaled Gauss-Newton step along it is unbounded (12 rad), and the trust region
    crawls: 44 evaluations for 0.42 % of the cost. The parametrisation holds a pair in the upper half
    plane, so a pair the data want as two distinct real poles (two roll-off corners) runs to theta = 0
    and stays there. The two real poles have decay rates (1 +- _NEAR_REAL_SPLIT) d (inside the decay
    bound ``margin`` when the pair is): the response moves by O(_NEAR_REAL_SPLIT^2), and from there
    the same block took 16 evaluations to a lower cost (1016 noise variances sigma^2 below the start,
    against 420). ``identify`` asks for it
    in the final refinement only: every refit of the order search and the delay steps split too sends
    their chains elsewhere (random helmet 6, thesis length: n 16 and 6.4 s of CPU against n 14, 4.5 s).
    """
    poles = np.asarray(poles, dtype=complex)
    decay = -np.log(np.maximum(np.abs(poles), 1e-300))
    near = (poles.imag > 1e-12) & (np.abs(np.angle(poles)) < _NEAR_REAL * decay)
    if not np.any(near):
        return poles
    keep = np.ones(poles.size, dtype=bool)
    split = []
    for p, d in zip(poles[near], decay[near]):
        keep &= np.abs(poles - np.conj(p)) > 1e-15
        faster = np.exp(-(1 + _NEAR_REAL_SPLIT) * d)
        slower = np.exp(-max((1 - _NEAR_REAL_SPLIT) * d, margin))
        split += [faster, slower]
    keep &= ~near
    return np.concatenate([poles[keep], np.array(split, dtype=complex)])


def _params_to_poles(params: np.ndarray, pairs: int, margin: float = _STABLE) -> np.ndarray:
    sigma, theta = params[0:2 * pairs:2], params[1:2 * pairs:2]
    # The margin keeps |p| below 1, and within what the block resolves, however far sigma or xi run.
    r = np.exp(-np.exp(np.minimum(sigma, 700.0)) - margin)
    upper = r * np.exp(1j * theta)
    return np.concatenate([upper, np.conj(upper), (np.exp(-margin) * np.tanh(params[2 * pairs:])).astype(complex)])


def _pole_derivatives(params: np.ndarray, pairs: int, margin: float) -> np.ndarray:
    """d pole / d parameter, one per parameter: -e^sigma p and j p for a pair's (sigma, theta)
    (upper pole), exp(-margin) (1 - tanh^2 xi) for a real pole's xi."""
    upper = _params_to_poles(params, pairs, margin)[:pairs]
    out = np.empty(params.size, dtype=complex)
    out[0:2 * pairs:2] = -np.exp(np.minimum(params[0:2 * pairs:2], 700.0)) * upper
    out[1:2 * pairs:2] = 1j * upper
    out[2 * pairs:] = np.exp(-margin) * (1 - np.tanh(params[2 * pairs:]) ** 2)
    return out


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


def _minimum_norm(q: np.ndarray, r: np.ndarray, rhs: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Minimum-norm least-squares solution of (Q R) x = rhs for a rank-deficient R, as ``np.linalg.lstsq``
    on Q R (same singular values, same cut-off eps max(shape)), but by the SVD of the small R
    (Q has orthonormal columns): on the tall matrix it took 37 ms a call (random helmet 0, thesis-length
    session), on R well under 1 ms."""
    return np.linalg.lstsq(r, q.T @ rhs, rcond=np.finfo(float).eps * max(shape))[0]


def _shifted_cholesky_qr(matrix: np.ndarray, gram: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Thin (Q, R) of a full-rank ``matrix`` (m x n) by shifted CholeskyQR3, or None where a Cholesky step fails.

    Fukaya, Kannan, Nakatsukasa, Yamamoto, Yanagisawa, "Shifted Cholesky QR for computing the QR
    factorization of ill-conditioned matrices", SIAM J. Sci. Comput. 42(1), 2020: the Cholesky
    factor R1 of the shifted Gram matrix X^T X + s I, s = 11 (m n + n (n + 1)) u ||X||_2^2 (u the unit
    round-off), exists for any condition number up to about 1/u, and Q1 = X R1^-1 has a condition number
    small enough for CholeskyQR2 (two more steps Q_i = Q_(i-1) R_i^-1, R_i the Cholesky factor of
    Q_(i-1)^T Q_(i-1)) to bring it to orthogonality and a residual X - Q R of order u. Every step is a
    Gram matrix or a triangular solve with many right-hand sides (level-3 BLAS). ``gram`` is X^T X.
    """
    m, n = matrix.shape
    shift = 11.0 * (m * n + n * (n + 1)) * _UNIT_ROUNDOFF * np.linalg.eigvalsh(gram)[-1]
    r, info = lapack.dpotrf(gram + shift * np.eye(n), lower=0, clean=1)
    if info != 0:
        return None
    q = blas.dtrsm(1.0, r, matrix, side=1)
    for _ in range(2):
        step, info = lapack.dpotrf(q.T @ q, lower=0, clean=1)
        if info != 0:
            return None
        q = blas.dtrsm(1.0, step, q, side=1, overwrite_b=1)
        r = step @ r
    return q, r


def _condition_below(r: np.ndarray, limit: float) -> bool:
    """Whether the 2-norm condition number of the upper triangular r is below ``limit``, as
    ``np.linalg.cond(r) < limit`` but by bounds first: max|r_ii| / min|r_ii| <= cond_2(r) <= ||r||_F ||r^-1||_F
    (the diagonal holds r's eigenvalues, and |lambda| lies between the extreme singular values), the
    singular values only where the bounds straddle the limit. An SVD of a 46 x 46 factor took 340 us, the
    bounds (one triangular inverse) 36 us; identify asks this of every regressor it factors (1015 on random
    helmet 4, thesis length)."""
    diagonal = np.abs(np.diag(r))
    if not diagonal.size:
        return True
    if not np.all(np.isfinite(r)) or diagonal.min() == 0 or diagonal.max() >= limit * diagonal.min():
        return False
    inverse, info = lapack.dtrtri(r, lower=0)
    if info == 0 and np.all(np.isfinite(inverse)) and np.linalg.norm(r) * np.linalg.norm(inverse) < limit:
        return True
    return bool(np.linalg.cond(r) < limit)


class _Factor:
    """Thin QR factors Phi = Q R of a tall regressor with unit-norm columns, and least squares by them.

    When R is well conditioned, R is the Cholesky factor of the Gram matrix Phi^T Phi and Q stays
    implicit, Phi R^-1 (products Q^T X = R^-T Phi^T X and Q Y = Phi R^-1 Y): a single-threaded
    Householder QR of a 99600 x 34 block took 98 ms, its Gram matrix 8 ms (LAPACK's QR of a narrow
    matrix runs at matrix-vector speed). The Gram matrix squares the condition number kappa,
    losing about eps kappa^2 of orthogonality in Q: below kappa = _GRAM_CONDITION that is 1e-6 at
    most, far below what the Jacobian needs, and the least-squares solution takes one step of
    iterative refinement on the true residual (Bjorck, Numerical Methods for Least Squares
    Problems, 1996, sec. 2.9).

    Otherwise the columns are first split by a Cholesky factorisation of the Gram matrix with
    diagonal pivoting (LAPACK dpstrf; Higham, "Accuracy and Stability of Numerical Algorithms",
    2002, sec. 10.3): the columns kept, Phi_1, and those whose distance from the span of the kept
    ones is below _DEPENDENT_DISTANCE. Coinciding poles make such columns (two real poles
    at z = 0 or at the radius bound give identical columns; 304 of the 822 factorisations of random
    helmet 1's thesis-length session), and most ill-conditioned regressors are of that kind.
    - Some dropped: each is written Phi_2 = Phi_1 W on the kept columns (W by their own least
      squares) and accepted when Phi_2 - Phi_1 W is below the minimum-norm cut-off of
      ``np.linalg.lstsq`` (eps max(shape) ||Phi||_2 per column; a dropped column farther than that
      is kept and the rest tried again): then the range of Phi is that of Phi_1, Q and R are Phi_1's
      (implicit below _GRAM_CONDITION, else shifted CholeskyQR3) and the minimum-norm solution and
      the pseudo-inverse follow from W in closed form (``solve``, ``pinv_t``). Householder gave the
      same solution, but its R had a pivot of 1e-17 there, and R^-T in the Jacobian's second term
      made the coinciding poles' Jacobian columns about 1e14 in size, which froze those poles.
    - None dropped, or the dropped ones not accepted: Q and R of all columns by shifted
      CholeskyQR3 (``_shifted_cholesky_qr``).
    - Where a Cholesky step of that fails (rank deficient beyond what the split accepted): the
      explicit Householder factors, with a minimum-norm solution when R is rank deficient.
    Of 93 ill-conditioned regressors sampled from random helmet 1 (thesis length), 58 took the split
    with implicit Q, 18 the split with shifted CholeskyQR3, 16 shifted CholeskyQR3 of all columns and
    1 Householder: 0.43 s against Householder's 0.81 s for all 93 (one BLAS thread); a 99600 x 38
    block of the final refinement with two coinciding poles 19 ms against 89 ms.
    """

    def __init__(self, matrix: np.ndarray):
        self.matrix, self.q, self.keep, self.drop, self.w = matrix, None, None, None, None
        gram = matrix.T @ matrix
        try:
            r = scipy.linalg.cholesky(gram, lower=False, check_finite=False)
            implicit = _condition_below(r, _GRAM_CONDITION)
        except np.linalg.LinAlgError:
            implicit = False
        if implicit:
            self.r = r
        elif not self._split(matrix, gram):
            self.q, self.r = scipy.linalg.qr(matrix, mode="economic", check_finite=False)

    def _split(self, matrix: np.ndarray, gram: np.ndarray) -> bool:
        """The ill-conditioned routes of the class docstring; False where only Householder remains."""
        m, n = matrix.shape
        _, order, rank, _ = lapack.dpstrf(gram, tol=_DEPENDENT_DISTANCE**2 * max(np.max(np.diag(gram)), 1e-300))
        order = order[:n] - 1
        if rank < n:
            cutoff = np.finfo(float).eps * max(m, n) * np.sqrt(np.linalg.eigvalsh(gram)[-1])
            keep, drop = np.sort(order[:rank]), np.sort(order[rank:])
            distance = self._drop(matrix, gram, keep, drop, cutoff)
            if distance is not None and np.any(distance > cutoff) and np.any(distance <= cutoff):
                # Columns nearer the others than the pivoting resolves but farther than the cut-off: kept
                # (least squares resolves them), the rest dropped again on the wider set of kept columns.
                keep, drop = np.sort(np.concatenate([keep, drop[distance > cutoff]])), drop[distance <= cutoff]
                distance = self._drop(matrix, gram, keep, drop, cutoff)
            if distance is not None and np.all(distance <= cutoff):
                self._spread = scipy.linalg.cho_factor(np.eye(keep.size) + self.w @ self.w.T, check_finite=False)
                return True
            self.q, self.keep, self.drop, self.w = None, None, None, None
        factors = _shifted_cholesky_qr(matrix, gram)
        if factors is None:
            return False
        self.q, self.r = factors
        return True

    def _drop(self, matrix: np.ndarray, gram: np.ndarray, keep: np.ndarray, drop: np.ndarray,
              cutoff: float) -> np.ndarray | None:
        """Factor the ``keep`` columns (implicit below _GRAM_CONDITION, else shifted CholeskyQR3), write the
        ``drop`` columns on them (W) and return each dropped column's distance from their span (None where
        a Cholesky step fails); ``cutoff`` is the distance below which a column counts as dependent."""
        dropped = matrix[:, drop]
        sub_gram = gram[np.ix_(keep, keep)]
        try:
            r = scipy.linalg.cholesky(sub_gram, lower=False, check_finite=False)
            implicit = _condition_below(r, _GRAM_CONDITION)
        except np.linalg.LinAlgError:
            implicit = False
        self.keep = keep
        if implicit:
            self.q, self.r = None, r
        else:
            factors = _shifted_cholesky_qr(np.asfortranarray(matrix[:, keep]), sub_gram)
            if factors is None:
                return None
            self.q, self.r = factors
        if self.q is None:
            # Phi_1^T Phi_2 is in the Gram matrix already; one step of iterative refinement where the
            # distances are not yet below the cut-off (the implicit Q is accurate to eps kappa^2 only).
            w = scipy.linalg.cho_solve((self.r, False), gram[np.ix_(keep, drop)], check_finite=False)
        else:
            w = self._least_squares(dropped)
        left = dropped - self._kept_times(w)
        distance = np.sqrt(np.einsum("ij,ij->j", left, left))
        if self.q is None and np.max(distance) > cutoff:
            w += self._least_squares(left)
            left = dropped - self._kept_times(w)
            distance = np.sqrt(np.einsum("ij,ij->j", left, left))
        self.drop, self.w = drop, w
        return distance

    def _least_squares(self, rhs: np.ndarray) -> np.ndarray:
        """R^-1 Q^T rhs: least squares on the factored columns (all, or the kept ones)."""
        return scipy.linalg.solve_triangular(self.r, self.qt(rhs), check_finite=False)

    @property
    def columns(self) -> int:
        """Columns of the regressor."""
        return self.r.shape[0] if self.keep is None else self.keep.size + self.drop.size

    def _kept_times(self, y: np.ndarray) -> np.ndarray:
        """Phi_1 y: the kept columns (all when none are dropped) times y."""
        if self.keep is None:
            return self.matrix @ y
        full = np.zeros((self.matrix.shape[1],) + y.shape[1:])
        full[self.keep] = y
        return self.matrix @ full

    def qt(self, x: np.ndarray) -> np.ndarray:
        """Q^T x."""
        if self.q is not None:
            return self.q.T @ x
        product = self.matrix.T @ x
        if self.keep is not None:
            product = product[self.keep]
        return scipy.linalg.solve_triangular(self.r, product, trans="T", check_finite=False)

    def q_times(self, y: np.ndarray) -> np.ndarray:
        """Q y."""
        if self.q is not None:
            return self.q @ y
        return self._kept_times(scipy.linalg.solve_triangular(self.r, y, check_finite=False))

    def pinv_t(self, g: np.ndarray) -> np.ndarray:
        """c with Q c = (Phi^+)^T g (one row of g per regressor column): R^-T g at full rank. With
        dropped columns Phi = Phi_1 [I W] (columns permuted), Phi^+ = [I; W^T] (I + W W^T)^-1 Phi_1^+, so
        c = R^-T (I + W W^T)^-1 (g_kept + W g_dropped)."""
        if self.keep is not None:
            g = scipy.linalg.cho_solve(self._spread, g[self.keep] + self.w @ g[self.drop], check_finite=False)
        return scipy.linalg.solve_triangular(self.r, g, trans="T", check_finite=False)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """The least-squares solution x of Phi x = rhs (minimum-norm when Phi is rank deficient)."""
        if self.keep is not None:
            # Minimum norm over the kept and dropped coefficients: the pseudo-inverse of pinv_t's docstring.
            x = self._least_squares(rhs)
            if self.q is None:
                x += self._least_squares(rhs - self._kept_times(x))
            kept = scipy.linalg.cho_solve(self._spread, x, check_finite=False)
            out = np.empty(self.columns)
            out[self.keep], out[self.drop] = kept, self.w.T @ kept
            return out
        if self.q is None:
            x = self._least_squares(rhs)
            return x + self._least_squares(rhs - self.matrix @ x)
        diagonal = np.abs(np.diag(self.r))
        if diagonal.size and diagonal.min() > 1e-12 * diagonal.max():
            return scipy.linalg.solve_triangular(self.r, self.q.T @ rhs, check_finite=False)
        return _minimum_norm(self.q, self.r, rhs, self.matrix.shape)


def _qr_solve(matrix: np.ndarray, rhs: np.ndarray) -> tuple[_Factor, np.ndarray]:
    """(factors, x): the thin QR factors of ``matrix`` (``_Factor``) and the least-squares solution x of
    matrix x = rhs by them (several times faster than the SVD-based lstsq)."""
    factor = _Factor(matrix)
    return factor, factor.solve(rhs)


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
        scaled = _qr_solve(real, rhs)[1]
        return A, C, scaled / scale, rhs - real @ scaled


def _block_basis(pole: complex, z: np.ndarray) -> np.ndarray:
    """``modal_basis`` columns of one block: a pair a +- jb with C = [1, 0], or a real pole with C = [1]."""
    if pole.imag == 0:
        return (1.0 / (z - pole.real))[:, None]
    a, b = pole.real, pole.imag
    den = (z - a) ** 2 + b**2
    return np.stack([(z - a) / den, b / den], axis=1)


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
        poles = _params_to_poles(x, self.pairs, self.margin)
        _, _, real, scale, rhs = self.problem.regression(poles)
        factor, scaled = _qr_solve(real, rhs)
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
        zc = z[:, None]
        pc, rc = np.flatnonzero(is_pair), np.flatnonzero(~is_pair)
        dp = _pole_derivatives(x, pairs, self.margin)
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
    params, pairs = _poles_to_params(split_near_real_pairs(poles, margin) if split_near_real else poles, margin)
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
    stable = np.all(np.abs(_params_to_poles(solution, pairs, margin)) < 1.0)
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
        factor, scaled = _qr_solve(real, rhs)
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
