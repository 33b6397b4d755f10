"""Linear least squares on tall regressors with unit-norm columns, by thin QR factors of the Gram matrix.

The linear step of output-error refinement (``sysid.estimation.output_error``) solves a
least-squares problem on a regressor of a hundred thousand rows and a few dozen columns
at every evaluation of the criterion, and its Jacobian needs products with the factor Q
and the pseudo-inverse. ``Factor`` holds the thin factors Phi = Q R, by the Cholesky
factor of the Gram matrix when Phi is well conditioned (Q implicit), else by dropping the
columns that depend on the others (pivoted Cholesky), by shifted CholeskyQR3, or by
Householder; ``qr_solve`` factors and solves. Every route gives the minimum-norm solution
of ``np.linalg.lstsq``, several times faster (the class docstring has the measurements).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from scipy.linalg import blas, lapack

__all__ = ["Factor", "qr_solve"]

# Largest condition number of a regressor solved through its Gram matrix (``Factor``).
_GRAM_CONDITION = 1e5
# Distance (relative to the unit column norm) from the span of the other columns below which a column is
# tried as dependent (``Factor``): Gram-matrix pivoting resolves distances down to about sqrt(eps).
_DEPENDENT_DISTANCE = 1e-6
_UNIT_ROUNDOFF = np.finfo(float).eps / 2


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


class Factor:
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


def qr_solve(matrix: np.ndarray, rhs: np.ndarray) -> tuple[Factor, np.ndarray]:
    """(factors, x): the thin QR factors of ``matrix`` (``Factor``) and the least-squares solution x of
    matrix x = rhs by them (several times faster than the SVD-based lstsq)."""
    factor = Factor(matrix)
    return factor, factor.solve(rhs)
