"""The feed-forward filter in a Kautz basis: least mean band level under the band rule and a gain bound.

``BandLevelFit`` is step 2 of ``anc.feedforward``: W = sum c_i x_i in an orthonormal Kautz basis
(``anc.basis.KautzBasis``) whose poles come from the paths (``kautz_poles``), the coefficients
minimising the mean band level in dB (the sum over the bands with noise of log ear power) under
the band rule and a bound on W's mean-square gain outside the bands, all on a log-spaced grid.
The expected ear power includes what the FB model's error adds, s^2 |G|^2 |W|^2 Phi_xx per
frequency (``spread``: s = r95 ``anc.feedback.RMS_PER_95``, the MMSE treatment of a random model
error), with r95 capped at ``anc.uncertainty.LINEARISATION_LIMIT`` (100 %): beyond it the stated
bound is no longer a relative error (below the identification band it is the peak-based
"unknown" bound, 2300 at 19.9 Hz against 0.03 at 20.1 Hz on random helmet 1), and taken at face
value it made W switch off at 20 Hz like a brick wall, which no causal filter does without
giving up the bands above it (random helmet 1 on identified models: 4 dB mean 50 Hz-1 kHz
instead of 17). Where r95 reaches the cap W is halved (the MMSE shrink 1 / (1 + s^2)) and held by
the gain bound.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.optimize

from sysid.core.model import Model

from .basis import KautzBasis, qr_blocks
from .disturbance import Disturbance
from .feedback import RMS_PER_95
from .limits import FeedforwardProblem, chin_to_ear, region_index, regions
from .uncertainty import LINEARISATION_LIMIT, Uncertainty

__all__ = ["BandLevelFit", "kautz_poles", "path_poles", "rule_ratios", "spread"]

# Iterations of the dual problem (L-BFGS-B), rounds of the majorisation-minimisation and the change of
# every band's power (dB) below which it has settled.
_DUAL_ITERATIONS = 500
_MM_ROUNDS = 8
_MM_SETTLED_DB = 0.1
# Kautz poles: the slowest corner (Hz) any pole may have (a near-DC zero of S makes W integrate down to
# there; below the 20 Hz band there is nothing to control, and corners at 0.1 Hz put W's poles within
# 2e-6 of z = 1, which no fixed- or floating-point section of the board holds), the log-spaced set's range
# (Hz; the top as a fraction of fs) and density, and its dampings.
_SLOWEST_HZ = 15.0
_GENERIC_HZ = (15.0, 0.45)
_PER_DECADE = 8
_DAMPINGS = (0.05, 0.15, 0.5)
# Poles at the origin beyond W's own delay: an FIR part for the fastest detail.
_FIR_TAPS = 16
# The log-spaced grid of the fit and its blocks (``anc.basis.qr_blocks``).
_FIT_POINTS = 8192
_BLOCK = 1024
# W's gain bound below the grid's start holds down to here (Hz), on this many points: the criterion does not
# look there (no band), but a chin microphone's wind and handling noise does, and the board's fixed point would.
_SUBSONIC_HZ = 0.5
_SUBSONIC_POINTS = 64


def kautz_poles(s_model: Model, ff_model: Model | None, delay: int) -> np.ndarray:
    """Poles of W's Kautz basis (module docstring, step 2); radii at most that of a ``_SLOWEST_HZ`` corner."""
    fs = s_model.fs
    slowest = np.exp(-2.0 * np.pi * _SLOWEST_HZ / fs)
    zeros = s_model.zeros() if s_model.order else np.zeros(0, complex)
    zeros = zeros[np.isfinite(zeros)]
    zeros = np.where(np.abs(zeros) > 1.0, 1.0 / np.conj(zeros), zeros)
    path = ff_model.poles() if ff_model is not None and ff_model.order else np.zeros(0, complex)
    corners = np.geomspace(_GENERIC_HZ[0], _GENERIC_HZ[1] * fs, int(_PER_DECADE * np.log10(_GENERIC_HZ[1] * fs
                                                                                          / _GENERIC_HZ[0])) + 1)
    generic = [np.exp(-2.0 * np.pi * corners / fs)]
    for zeta in _DAMPINGS:
        generic.append(np.exp(2.0 * np.pi * corners / fs * (-zeta + 1j * np.sqrt(1.0 - zeta * zeta))))
    poles = np.concatenate([zeros, path, np.zeros(max(int(delay), 0) + _FIR_TAPS), *generic])
    radius = np.abs(poles)
    return np.where(radius > slowest, poles * slowest / np.maximum(radius, 1e-300), poles)


def path_poles(s_model: Model, ff_model: Model, loop_poles=None) -> np.ndarray:
    """Poles of W's Kautz basis from the paths alone: those of the filter that cancels the chin noise.

    With S_model = z^-d_S B S_o (``anc.outer_factor``: B the all-pass of S's zeros outside the unit circle), the
    feed-forward filter W = -(1 + G Q) z^L P / S_model has the poles of P, the zeros of S (those outside reflected
    inside, where B's causal part puts them) and, with Q (``loop_poles``: the poles of G Q, S's, Q's and the
    latency's), those of 1 + G Q; ``_FIR_TAPS`` poles at the origin hold the delays' remainder. The basis holds
    that filter in a few dozen functions beside Q's where the generic basis (``kautz_poles``) needs hundreds:
    random pair 3/1005 under the board's cap (W 96 states, Q 61), 40.4 dB predicted with Q against 12.4 of the
    generic fit truncated; the chin path's lead (24 samples) and S's delay as further poles at the origin
    lowered it to 36.7 and 24.4 dB (the cap truncates them). Radii at most that of a ``_SLOWEST_HZ`` corner."""
    fs = s_model.fs
    slowest = np.exp(-2.0 * np.pi * _SLOWEST_HZ / fs)
    zeros = s_model.zeros() if s_model.order else np.zeros(0, complex)
    zeros = zeros[np.isfinite(zeros)]
    zeros = np.where(np.abs(zeros) > 1.0, 1.0 / np.conj(zeros), zeros)
    p_poles = ff_model.poles() if ff_model.order else np.zeros(0, complex)
    loop = np.zeros(0, complex) if loop_poles is None else np.asarray(loop_poles, dtype=complex).reshape(-1)
    poles = np.concatenate([zeros, p_poles, np.zeros(_FIR_TAPS), loop])
    radius = np.abs(poles)
    return np.where(radius > slowest, poles * slowest / np.maximum(radius, 1e-300), poles)


class BandLevelFit:
    """W = sum c_i x_i in a Kautz basis of least mean band ear power (log) under the band rule (module docstring).

    On a log-spaced grid (trapezoid weights q) the ear power with W in a region r (``anc.limits.regions``: a
    band of ``anc.prediction``, or a region outside them) is a quadratic in c,
    P_r(c) = sum q Phi_xx (|t + G W|^2 + R |W|^2) + (incoherent power), for the target t = H (W alone)
    or T (with Q). In whitened coordinates y = R_J c (R_J from the QR factorisation of J, ``anc.basis.qr_blocks``,
    with a ridge of 1e-12 of its mean diagonal) every P_r is y' A_r y + 2 q_r' y + k_r, well conditioned.

    Criterion: the sum over the bands with noise of log P_r (the mean attenuation in dB: each band
    counts as the listener's band level does, the loud low bands do not drown the rest) plus the ear power
    outside the bands relative to the total without W, minimised by
    majorisation-minimisation (Hunter & Lange, Am. Stat. 58(1), 2004): log P <= log P_k + P / P_k - 1, so
    each round minimises sum P_r / P_r(y_k) and never raises the criterion. The first round minimises the
    ear power itself (the filter of least ear power under the rule), so the result is at least as good as
    that one in every measure the rounds improve. Band rule per round: with
    multipliers mu >= 0 the Lagrangian is again a quadratic, minimised by one n x n solve, and its
    dual (concave, gradient P_b / P_b(0) - 10^(tol / 10)) is maximised by L-BFGS-B (Boyd & Vandenberghe,
    "Convex Optimization", 2004, sec. 5.2; W = 0 is strictly feasible, so strong duality holds).
    """

    def __init__(self, problem: FeedforwardProblem, s_model: Model, disturbance: Disturbance, ff_model,
                 uncertainty: Uncertainty | None, loop, basis: KautzBasis, max_gain: float):
        fs, L, n = s_model.fs, problem.latency, basis.size
        self.problem, self.basis = problem, basis
        f = np.concatenate(([0.0], np.geomspace(_SLOWEST_HZ / 2.0, fs / 2.0, _FIT_POINTS)))
        error = spread(uncertainty, f)
        G = s_model.frequency_response(f) * np.exp(-2j * np.pi * f * L / fs)
        H = chin_to_ear(disturbance, ff_model, f)
        one_plus = 1.0 if loop is None else 1.0 + loop(f)
        quadrature = np.gradient(f)
        weight = quadrature * np.interp(f, problem.f, problem.phi)
        effort = problem.effort + error * np.abs(G) ** 2
        uu = quadrature * np.interp(f, problem.f, problem.uu)
        region = region_index(f, fs)
        self.regions = len(regions(fs))
        targets = [H] + ([one_plus * H] if loop is not None else [])
        floors = [uu] + ([np.abs(one_plus) ** 2 * uu] if loop is not None else [])

        def blocks():
            for start in range(0, f.size, _BLOCK):
                k = slice(start, start + _BLOCK)
                responses = basis.responses(f[k], fs)
                yield k, responses, (np.sqrt(weight[k]) * G[k])[:, None] * responses, \
                    np.sqrt(weight[k] * effort[k])[:, None] * responses

        R, _ = qr_blocks(((np.vstack([m, e]), np.zeros(2 * m.shape[0])) for _, _, m, e in blocks()), n)
        ridge = np.sqrt(1e-12 * max(float(np.sum(R * R)) / n, 1e-300))
        R, _ = qr_blocks([(np.vstack([R, ridge * np.eye(n)]).astype(complex), np.zeros(2 * n))], n)
        self.R_inv = scipy.linalg.solve_triangular(R, np.eye(n))
        self.A = np.zeros((self.regions, n, n))
        gain = np.zeros((self.regions, n, n))
        width = np.zeros(self.regions)
        self.q = np.zeros((len(targets), self.regions, n))
        self.k = np.zeros((len(targets), self.regions))
        for k, responses, m, e in blocks():
            m, e = m @ self.R_inv, e @ self.R_inv
            plain = np.sqrt(quadrature[k])[:, None] * responses @ self.R_inv
            r = region[k]
            for index in np.unique(r):
                rows = r == index
                self.A[index] += np.real(m[rows].conj().T @ m[rows]) + np.real(e[rows].conj().T @ e[rows])
                gain[index] += np.real(plain[rows].conj().T @ plain[rows])
                width[index] += float(np.sum(quadrature[k][rows]))
                for case, (target, floor) in enumerate(zip(targets, floors)):
                    t = np.sqrt(weight[k][rows]) * target[k][rows]
                    self.q[case, index] += np.real(np.conj(t) @ m[rows])
                    self.k[case, index] += float(np.sum(np.abs(t) ** 2) + np.sum(floor[k][rows]))
        subsonic = np.geomspace(_SUBSONIC_HZ, f[1], _SUBSONIC_POINTS, endpoint=False)
        plain = np.sqrt(np.gradient(subsonic))[:, None] * basis.responses(subsonic, fs) @ self.R_inv
        below = region_index(subsonic[:1], fs)[0]
        gain[below] += np.real(plain.conj().T @ plain)
        width[below] += float(np.sum(np.gradient(subsonic)))
        self.ridge = np.eye(n) * 1e-12 * float(np.trace(np.sum(self.A, axis=0))) / n
        self.objective = len(targets) - 1
        self.noisy = np.append(problem.audible, np.zeros(self.regions - problem.bands, bool))
        # The constraints c_i(y) = s_i (y' A_i y + 2 q_i' y + k_i) <= limit_i: the band rule in every band with
        # noise, alone and with Q (s = 1 / power without W), and W's mean-square gain outside the bands.
        bands = np.flatnonzero(problem.audible)
        outside = np.arange(problem.bands, self.regions)
        outside = outside[width[outside] > 0.0]
        self.constraint_A = np.concatenate([np.repeat(self.A[bands][None], len(targets), axis=0).reshape(-1, n, n),
                                            gain[outside]])
        self.constraint_q = np.concatenate([self.q[:, bands].reshape(-1, n), np.zeros((outside.size, n))])
        self.constraint_k = np.concatenate([self.k[:, bands].reshape(-1), np.zeros(outside.size)])
        self.constraint_s = np.concatenate([1.0 / self.k[:, bands].reshape(-1), 1.0 / (max_gain ** 2 * width[outside])])
        self.is_band = np.arange(self.constraint_k.size) < bands.size * len(targets)
        self.constraint_where = np.concatenate([np.tile(bands, len(targets)), outside])
        self.outside, self.gain, self.width = outside, gain[outside], width[outside]

    def powers(self, y: np.ndarray) -> np.ndarray:
        """(cases, regions): the ear power per region with W = y (whitened), W alone and (if any) with Q."""
        return _quadratic_forms(self.A, y)[None, :] + 2.0 * self.q @ y + self.k

    def _minimiser(self, region_weight: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """argmin of sum_r w_r P_r + sum_i mu_i c_i: one solve."""
        w = mu * self.constraint_s
        n = self.ridge.shape[0]
        K = (region_weight @ self.A.reshape(self.A.shape[0], -1) + w @ self.constraint_A.reshape(w.size, -1)).reshape(n, n)
        K = K + self.ridge
        return np.linalg.solve(K, -(region_weight @ self.q[self.objective] + w @ self.constraint_q))

    def _constrained(self, region_weight: np.ndarray, limit: np.ndarray,
                     mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(y, mu): the minimiser of sum w_r P_r under the constraints, by the dual (class docstring), from mu."""

        def dual(mu):
            y = self._minimiser(region_weight, mu)
            values = self.constraint_s * (_quadratic_forms(self.constraint_A, y) + 2.0 * self.constraint_q @ y
                                          + self.constraint_k) - limit
            objective = float(region_weight @ self.powers(y)[self.objective])
            return -(objective + float(mu @ values)), -values

        if np.any(dual(mu)[1] < 0.0) or np.any(mu > 0.0):
            mu = np.maximum(scipy.optimize.minimize(dual, mu, jac=True, method="L-BFGS-B", bounds=[(0.0, None)] * mu.size,
                                                    options={"maxiter": _DUAL_ITERATIONS}).x, 0.0)
        return self._minimiser(region_weight, mu), mu

    def band_limits(self, limit_db: float, tolerance_db: float) -> np.ndarray:
        """Per constraint, the largest ratio of its power to its power without W (``rule_ratios`` on this grid's
        powers); 1 for the gain bound (its own scale)."""
        cases = self.k.shape[0]
        bands = self.constraint_where[self.is_band][:int(np.sum(self.is_band)) // cases]
        ratios = rule_ratios(self.k[0, bands], self.k[-1, bands] if cases > 1 else None, limit_db, tolerance_db)
        return np.concatenate([ratios.reshape(-1), np.ones(int(np.sum(~self.is_band)))])

    def gain_squared(self, y: np.ndarray) -> np.ndarray:
        """W's mean-square gain in each region outside the bands (``outside``), for W = y (whitened)."""
        return _quadratic_forms(self.gain, y) / self.width

    def design(self, limit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(c, mu): the coefficients of least mean log band power under the constraints (``limit``: per constraint,
        ``band_limits``), and the multipliers."""
        # Start from the ear power itself (every region, weight 1 / total): the filter of least ear power under the
        # rule; the rounds then only lower the criterion from there. Outside the bands the ear power keeps that
        # weight in every round (W is held there by it and by its gain bound, not by the bands' criterion).
        ear_power = np.full(self.regions, 1.0 / float(np.sum(self.k[self.objective])))
        region_weight = ear_power
        previous = None
        mu = np.zeros(self.constraint_k.size)
        for _ in range(_MM_ROUNDS):
            y, mu = self._constrained(region_weight, limit, mu)
            power = self.powers(y)[self.objective]
            if previous is not None and np.max(np.abs(10.0 * np.log10(power / previous))[self.noisy]) < _MM_SETTLED_DB:
                break
            previous = power
            region_weight = np.where(self.noisy, 1.0 / np.maximum(power, 1e-300), ear_power)
        return self.R_inv @ y, mu


def rule_ratios(off: np.ndarray, with_q: np.ndarray | None, limit_db: float, tolerance_db: float) -> np.ndarray:
    """(cases, bands): the band rule (``anc.feedforward``) as the largest ratio of ear power with W to without it,
    from the power per band with no control (``off``) and with Q alone (``with_q``; None without a loop): W alone
    ``limit_db`` above no control; W with Q ``limit_db`` above no control, or ``tolerance_db`` above Q alone where
    Q alone is already that loud."""
    limit = 10.0 ** (limit_db / 10.0)
    rows = [np.full(np.shape(off), limit)]
    if with_q is not None:
        rows.append(np.maximum(limit * off / np.maximum(with_q, 1e-300), 10.0 ** (tolerance_db / 10.0)))
    return np.array(rows)


def spread(uncertainty: Uncertainty | None, frequencies_hz: np.ndarray) -> np.ndarray | float:
    """s^2 at frequencies (Hz): the FB model's mean-square relative error, r95 ``RMS_PER_95`` with r95 capped
    at ``anc.uncertainty.LINEARISATION_LIMIT`` (module docstring); 0 without an uncertainty."""
    if uncertainty is None:
        return 0.0
    return (np.minimum(uncertainty.at(frequencies_hz), LINEARISATION_LIMIT) * RMS_PER_95) ** 2


def _quadratic_forms(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    """y' A_m y for each matrix of the stack A (m, n, n), as one matrix product."""
    return (A.reshape(-1, y.size) @ y).reshape(A.shape[0], y.size) @ y
