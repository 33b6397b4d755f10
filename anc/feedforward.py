"""Feed-forward filter W from the chin reference: least band levels under the band rule, at the order it needs.

With d = H x + u (H the chin-to-ear response: the FF model P, or the recording's coherent
response; u not coherent with the chin), the feedback loop 1 + G Q acting on d (``anc.feedback``;
Q = 0 without feedback) and G = z^-L S_model, the ear is e = (1 + G Q) d + G W x, T = (1 + G Q) H.
``design_feedforward`` in three steps:

1. The causal Wiener filter of any length for the models and the user's noise (``anc.wiener``,
   Bode-Shannon, on the dense FFT grid of ``anc.limits.FeedforwardProblem``): the filter of least
   ear power in the bands' measure (the causal bound of ``anc.limits``, here with the FB model's
   error as a penalty), the reference the design is reported against (``full_db``), and where W's
   delay is read (its impulse response's onset) for the basis poles.
2. W in an orthonormal Kautz basis with poles from the paths (``anc.feedforward_fit``): the
   coefficients of least mean band level in dB over the bands with noise, under the band rule and
   a bound on W's gain outside the bands, for the expected ear power under the FB model's error.
   Band rule (``allowed_ratio``): W makes no band 20 Hz-2 kHz (``anc.prediction``) with noise in it
   (``anc.limits.SILENT_BAND``) more than the stated amplification limit louder than with ANC off (the limit Q
   keeps, ``anc.design.DesignOptions.max_amplification_db``, 6 dB by default), alone and with Q; where Q alone
   is already that loud W adds at most ``BAND_TOLERANCE_DB``. A causal W has a trade of its own wherever it
   cannot cancel: S's zeros outside the unit circle and a chin path faster than the drive path leave it a
   filter that is right in some bands only if it is wrong in others. Held to 0.1 dB louder (the rule until
   2026-11) W gave up those bands: random pair 13/1013 (S's zero at 598 Hz, radius 1.0041; the chin path
   13 samples ahead) 10.1 dB judged 'both' against 20.3 at the stated limit, the seed pair 16.4 against 19.2,
   its bands at most 2.8 dB louder on the true plants. The fit holds the rule at ``_FIT_SHARE`` of the limit,
   leaving the rest to the truncation and to the models' error. Gain bound: outside the bands W's mean-square
   gain per region (``anc.limits.regions``) stays below ``max_gain_db``, below the bands down to 0.5 Hz; designed on
   the true seed plants without it, W had 74 dB of gain above 5 kHz, where the recording's chin is at its floor,
   and with the bound held from 7.5 Hz only (the fit's grid), random pair 13/1013's W had 62 dB at 2 Hz (its Q15
   round-off SNR 23.1 dB against 44.0 with the bound down to 0.5 Hz, "both" unchanged at 20.7 dB).
   Mean band level rather than ear power: ear power is the loud low bands' (pink noise), and the
   least-ear-power filter trades every band for them. On the seed pair (identified models, the
   recording of ``tests/control_cases``, latency 2) the causal bound is 11.6 dB mean over
   50 Hz-1 kHz, capped by S's zero at z = 1.0089 whose phase turns at 62 Hz; the mean-level filter
   gives up 20-160 Hz and reaches 14.4 dB judged on the true plants (14.4 predicted): the zero
   costs around its corner, not octaves above it. The fit starts from the least-ear-power filter under the same
   constraints and only lowers the mean level from there.
   W is fitted in two bases, the better kept (mean 50 Hz-1 kHz with Q where there is one): the generic one
   (``anc.feedforward_fit.kautz_poles``, hundreds of functions) and one of the paths' own poles
   (``anc.feedforward_fit.path_poles``: S's zeros, P's poles and the loop's, a few dozen beside Q's), which
   holds -(1 + G Q) z^L P / S whenever the chin path is the slower one and so survives the board's cap
   (random pair 3/1005 at Q 61 / W 96 states: 'both' 12.4 -> 40.4 dB predicted; seed 9.1 -> 16.3).
3. Balanced truncation (``sysid.core.lti.minimal_balanced_realisation``) to the lowest order whose
   attenuation in every band with noise stays within ``REALISATION_TOLERANCE_DB`` (0.5 dB) of the
   full order's and that keeps the band rule and the gain bound; if the truncated filter breaks the
   rule by rounding, it is scaled to the largest factor that keeps it. Under the board's cap (``max_order``)
   the search ends at the cap; where the truncation there breaks the rule (on the seed at every cap below
   the default: the truncated W sits on the rule at 18-141 Hz), the truncation's poles keep their places
   and their output weights (``anc.basis.StateBasis``) are fitted again by step 2, the better kept: on the
   seed 4.7 / 7.6 / 12.9 dB judged at 40 / 80 / 120 states against 14.4 at 273 (plain truncation 0.0 / 0.2).

Attenuation is predicted on the dense grid's bins inside each band, the same bins as the limits
(``anc.limits.feedforward_limits``). The old design (the bound |G W + T| <= 2 |T| on 0 - fs/2 by
reweighting, 24 Laguerre functions at 250 Hz, the default spectrum) gave the seed 0.1 dB.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from sysid.core.lti import minimal_balanced_realisation, state_responses
from sysid.core.model import Model

from .basis import KautzBasis, StateBasis
from .controller import StateSpaceFilter
from .disturbance import Disturbance
from .feedforward_fit import BandLevelFit, kautz_poles, path_poles, rule_ratios, spread
from .limits import CHIN_FLOOR, MAX_AMPLIFICATION_DB, MAX_GAIN_DB, FeedforwardProblem, regions
from .prediction import band_centres, band_grid
from .uncertainty import Uncertainty

__all__ = ["FeedforwardDesign", "design_feedforward", "allowed_ratio", "BAND_TOLERANCE_DB", "REALISATION_TOLERANCE_DB",
           "MAX_GAIN_DB"]

# Where Q alone already makes a band as loud as the stated limit, W may add this much (the rounding of a fit).
BAND_TOLERANCE_DB = 0.1
# The stored filter's attenuation per band stays this close to the full order's.
REALISATION_TOLERANCE_DB = 0.5
# The bands a cap's cost is stated over (Hz): the judged third-octave bands.
JUDGED_HZ = (50.0, 1000.0)
# The fit holds the band rule to this fraction of its limit (dB), leaving the rest to the truncation and the models.
_FIT_SHARE = 0.5


@dataclass
class FeedforwardDesign:
    """W as stored (``filter``, balanced and truncated) and what it came from.

    ``attenuation_db`` / ``full_db``: per band (``anc.prediction.BANDS``, dB; W alone) of the stored
    filter and of the full causal Wiener filter of the design criterion, on the dense grid;
    ``with_loop_db`` / ``full_with_loop_db`` the same with Q against Q alone (None without Q);
    ``order`` / ``full_order`` the stored and the fitted filter's states; ``audible`` the bands with
    noise; ``grid_points`` the dense grid's length; ``notes`` say what limited it.
    """

    filter: StateSpaceFilter
    basis: KautzBasis
    coefficients: np.ndarray
    attenuation_db: np.ndarray
    full_db: np.ndarray
    with_loop_db: np.ndarray | None
    full_with_loop_db: np.ndarray | None
    audible: np.ndarray
    order: int
    full_order: int
    grid_points: int
    notes: list[str] = field(default_factory=list)

def _response(system, z: np.ndarray) -> np.ndarray:
    """C (zI - A)^-1 B + D at many points z (``sysid.core.lti.state_responses``)."""
    A, B, C, D = system
    d = float(np.asarray(D).reshape(-1)[0])
    if A.shape[0] == 0:
        return np.full(z.size, d, dtype=complex)
    return C[0] @ state_responses(A, B, z) + d


def _onset(impulse: np.ndarray) -> int:
    """Samples before W's impulse response first reaches a thousandth of its peak (its delay, for the poles)."""
    head = np.abs(impulse[: impulse.size // 2])
    return int(np.argmax(head > 1e-3 * float(np.max(head)))) if np.any(head > 0.0) else 0


def allowed_ratio(problem: FeedforwardProblem, limit_db: float) -> np.ndarray:
    """(cases, regions): the band rule (module docstring; ``anc.feedforward_fit.rule_ratios``) on the problem's
    regions, W alone and, with a loop, W with Q; no limit outside the rule."""
    with_q = problem.off_with_loop if problem.loop is not None else None
    return np.where(problem.ruled, rule_ratios(problem.off, with_q, limit_db, BAND_TOLERANCE_DB), np.inf)


def _louder_above(problem: FeedforwardProblem, attenuation: np.ndarray, limit_db: float) -> str | None:
    """The note where W alone (``attenuation``: ``problem.attenuation(W)``, every region) makes the ear more than
    ``limit_db`` louder above the bands (2 kHz to fs / 2) than without it, for the chin spectrum the limits take
    there (the recording's, floored at ``CHIN_FLOOR`` of its peak: a microphone's self-noise), else None. The band
    rule ends at the bands; above them only W's gain bound holds, and a recording with no chin noise there does
    not show what self-noise or wind would do (the seed pair's W: 51 dB at 2.2-4.5 kHz)."""
    nb = problem.bands
    louder = -attenuation[nb + 1:]
    worst = int(np.argmax(louder))
    if louder[worst] <= limit_db:
        return None
    lo, hi = regions(problem.fs)[nb + 1 + worst]
    return (f"W makes the ear {louder[worst]:.0f} dB louder at {lo / 1000:.1f}-{hi / 1000:.1f} kHz than without it, "
            f"for the chin noise the limits take there (the recording's, floored at {10 * np.log10(CHIN_FLOOR):.0f} dB "
            "of its peak for a microphone's self-noise); above 2 kHz no band rule holds, only W's gain bound")


def _excess(problem: FeedforwardProblem, W: np.ndarray, limit_db: float) -> np.ndarray:
    """Per region, dB beyond what the band rule allows (``allowed_ratio``; <= 0 where it holds)."""
    allowed = 10.0 * np.log10(allowed_ratio(problem, limit_db))
    excess = -problem.attenuation(W) - allowed[0]
    if problem.loop is not None:
        excess = np.maximum(excess, -problem.attenuation(W, with_loop=True) - allowed[1])
    return np.where(problem.ruled, excess, -np.inf)


def _largest_scale(problem: FeedforwardProblem, W: np.ndarray, limit_db: float) -> float:
    """Largest t in [0, 1] keeping the band rule (``allowed_ratio``) with t W (W on ``problem.checked``)."""
    allowed = allowed_ratio(problem, limit_db) - 1.0
    t = 1.0
    cases = [(problem.H, problem.off)] + ([(problem.T, problem.off_with_loop)] if problem.loop is not None else [])
    at = problem.checked
    for case, (target, off) in enumerate(cases):
        gw = problem.G[at] * W
        a = problem.band_sum(problem.phi[at] * np.abs(gw) ** 2)
        b = problem.band_sum(2.0 * problem.phi[at] * np.real(gw * np.conj(target[at])))
        c = np.where(problem.ruled, allowed[case], 0.0) * off
        # t^2 a + t b - c <= 0 holds on [0, root] (a >= 0, c >= 0): root = (-b + sqrt(b^2 + 4 a c)) / 2a.
        with np.errstate(divide="ignore", invalid="ignore"):
            root = np.where(a > 0, (-b + np.sqrt(b * b + 4.0 * a * c)) / (2.0 * np.where(a > 0, a, 1.0)), np.inf)
        t = min(t, float(np.min(np.where(problem.ruled, root, np.inf))))
    return max(t, 0.0)


def design_feedforward(s_model: Model, disturbance: Disturbance, latency: int, uncertainty: Uncertainty | None = None,
                       feedback_loop=None, ff_model: Model | None = None,
                       max_gain_db: float = MAX_GAIN_DB, max_order: int | None = None,
                       loop_poles=None, max_amplification_db: float = MAX_AMPLIFICATION_DB) -> FeedforwardDesign:
    """Feed-forward W (module docstring). ``feedback_loop(f)`` returns G Q at f (Hz), or None; ``ff_model``: P
    when the disturbance does not carry it; ``uncertainty``: the FB model's (None: the model taken as exact);
    ``max_order``: W's states at most (the board's budget; None: the lowest order within
    ``REALISATION_TOLERANCE_DB``), what the cap costs stated in the notes (mean 50 Hz-1 kHz).
    ``loop_poles``: the poles of G Q (S's, Q's and the latency's origin) for the basis of the paths' poles
    (``anc.feedforward_fit.path_poles``); W is fitted in it and in the generic basis, the better kept.
    ``max_amplification_db``: the band rule's limit (``allowed_ratio``; the stated amplification limit).

    One BLAS thread: the fit's solves and the truncation's Schur forms are of a few hundred rows, where
    threads on a busy machine cost seven times the CPU (seed pair: 4.9 s against 36.8 s)."""
    if max_order is not None and int(max_order) < 1:
        raise ValueError(f"max_order must be a positive number of states; found {max_order}")
    with threadpool_limits(limits=1, user_api="blas"):
        return _design(s_model, disturbance, latency, uncertainty, feedback_loop, ff_model, max_gain_db,
                       None if max_order is None else int(max_order), loop_poles, float(max_amplification_db))


def _design(s_model, disturbance, latency, uncertainty, feedback_loop, ff_model, max_gain_db,
            max_order, loop_poles, limit_db) -> FeedforwardDesign:
    ff_model = ff_model if ff_model is not None else disturbance.ff_model
    problem = FeedforwardProblem(s_model, disturbance, latency, ff_model, feedback_loop)
    full = problem.wiener(effort=problem.effort + spread(uncertainty, problem.f) * np.abs(problem.G) ** 2)
    generic = KautzBasis.from_poles(kautz_poles(s_model, ff_model, _onset(problem.grid.impulse_response(full))))
    designs = [_designed_in(generic, problem, full, s_model, disturbance, uncertainty, feedback_loop, ff_model,
                            max_gain_db, max_order, limit_db)]
    if ff_model is not None:
        paths = KautzBasis.from_poles(path_poles(s_model, ff_model, loop_poles))
        designs.append(_designed_in(paths, problem, full, s_model, disturbance, uncertainty, feedback_loop, ff_model,
                                    max_gain_db, max_order, limit_db))
    # The better in the judged bands with noise, with Q when there is one (what the listener hears).
    judged = np.array([JUDGED_HZ[0] <= centre <= JUDGED_HZ[1] for centre in band_centres()]) & problem.audible
    scores = [float(np.mean((d.with_loop_db if d.with_loop_db is not None else d.attenuation_db)[judged]))
              for d in designs]
    best = int(np.argmax(scores))
    chosen = designs[best]
    if len(designs) > 1:
        names = ("the generic basis", "the basis of the paths' poles")
        chosen.notes.append(f"W in {names[best]} ({chosen.basis.size - 1} functions): {scores[best]:.1f} dB mean "
                            f"50 Hz-1 kHz predicted, against {scores[1 - best]:.1f} dB in {names[1 - best]} "
                            f"({designs[1 - best].basis.size - 1} functions)")
    return chosen


def _designed_in(basis: KautzBasis, problem: FeedforwardProblem, full: np.ndarray, s_model, disturbance, uncertainty,
                 feedback_loop, ff_model, max_gain_db, max_order, limit_db) -> FeedforwardDesign:
    """W fitted in ``basis`` (step 2) and reduced to the order it needs or the cap (step 3)."""
    fs = s_model.fs
    notes: list[str] = []
    with_loop = problem.loop is not None
    max_gain = 10.0 ** (max_gain_db / 20.0)
    solver = BandLevelFit(problem, s_model, disturbance, ff_model, uncertainty, feedback_loop, basis, max_gain)
    c, mu = solver.design(solver.band_limits(_FIT_SHARE * limit_db, _FIT_SHARE * BAND_TOLERANCE_DB))
    fitted = basis.responses(problem.f[problem.checked], fs) @ c
    edges = regions(fs)
    rules = ((True, f"band rule (W makes no band with noise more than {limit_db:g} dB louder than with ANC off, "
                    "alone or with Q)"), (False, f"W's gain bound {max_gain_db:g} dB outside the bands"))
    for is_band, what in rules:
        binding = sorted(set(solver.constraint_where[(mu > 0.0) & (solver.is_band == is_band)]))
        if binding:
            notes.append(f"{what}: binding in {', '.join(f'{edges[r][0]:.0f}-{edges[r][1]:.0f} Hz' for r in binding)}")
    nb = problem.bands
    full_db = problem.attenuation(full)[:nb]
    full_loop_db = problem.attenuation(full, with_loop=True)[:nb] if with_loop else None
    balanced = minimal_balanced_realisation(*basis.statespace(c))
    n = balanced.A.shape[0]
    z_in = np.exp(2j * np.pi * problem.f[problem.checked] / fs)

    def truncated(k: int):
        system = (balanced.A[:k, :k], balanced.B[:k], balanced.C[:, :k], np.array([[balanced.D]]))
        return system, _response(system, z_in)

    reference = problem.attenuation(fitted)[:nb]
    reference_loop = problem.attenuation(fitted, with_loop=True)[:nb] if with_loop else None

    gain_limit = np.maximum(max_gain ** 2, problem.outside_gain(fitted)) * 10.0 ** (BAND_TOLERANCE_DB / 10.0)

    def acceptable(W: np.ndarray) -> bool:
        if np.any(problem.outside_gain(W) > gain_limit):
            return False
        close = np.all((problem.attenuation(W)[:nb] >= reference - REALISATION_TOLERANCE_DB)[problem.audible])
        if with_loop:
            close = close and np.all((problem.attenuation(W, with_loop=True)[:nb]
                                      >= reference_loop - REALISATION_TOLERANCE_DB)[problem.audible])
        return bool(close and np.all(_excess(problem, W, limit_db) <= 0.0))

    # The lowest acceptable order: doubling, then bisection between the last two (the attenuation grows with the
    # order, not strictly; the order found is acceptable, a lower one might be too).
    # Under a cap the search ends at it, and the cap is taken when no order below it is acceptable.
    top = n if max_order is None else min(n, max_order)
    high = 1
    while high < top and not acceptable(truncated(high)[1]):
        high *= 2
    high = min(high, top)
    low = high // 2
    while high - low > 1:
        middle = (low + high) // 2
        if acceptable(truncated(middle)[1]):
            high = middle
        else:
            low = middle
    system, W = truncated(high)
    capped = max_order is not None and high == top < n and not acceptable(W)
    if capped:
        # Truncation keeps the cap's poles; their output weights are fitted again under the same criterion and
        # constraints (the truncated weights break the band rule wherever W sits at it).
        states = StateBasis(system[0], system[1])
        refit = BandLevelFit(problem, s_model, disturbance, ff_model, uncertainty, feedback_loop, states, max_gain)
        weights, _ = refit.design(refit.band_limits(_FIT_SHARE * limit_db, _FIT_SHARE * BAND_TOLERANCE_DB))
        refitted = states.responses(problem.f[problem.checked], fs) @ weights

        def scaled_mean(W):
            return float(np.mean(problem.attenuation(_largest_scale(problem, W, limit_db) * W)[:nb][
                problem.audible]))

        if scaled_mean(refitted) > scaled_mean(W):
            system, W = states.statespace(weights), refitted
            notes.append(f"W at the cap: the truncated filter's {high} poles with their weights fitted again")
    t = _largest_scale(problem, W, limit_db)
    if t < 1.0:
        system = (system[0], system[1], system[2] * t, system[3] * t)
        W = W * t
        notes.append(f"W scaled by {t:.3f} to keep the band rule")
    attenuation = problem.attenuation(W)
    achieved = attenuation[:nb]
    shortfall = np.max(np.where(problem.audible, reference - achieved, -np.inf))
    above = _louder_above(problem, attenuation, limit_db)
    if above is not None:
        notes.append(above)
    if capped:
        judged = np.array([JUDGED_HZ[0] <= centre <= JUDGED_HZ[1] for centre in band_centres()]) & problem.audible
        notes.append(f"W capped at {high} states (max_order): {np.mean((reference - achieved)[judged]):.2f} dB "
                     f"below the full order's mean over the bands with noise {JUDGED_HZ[0]:g} Hz-"
                     f"{JUDGED_HZ[1] / 1000:g} kHz")
    notes.append(f"W: {basis.size - 1} Kautz functions, balanced truncation to order {high} (of {n}); at most "
                 f"{max(shortfall, 0.0):.2f} dB short of the full order in any band; mean "
                 f"{np.mean(achieved[problem.audible]):.1f} dB over the bands with noise against "
                 f"{np.mean(full_db[problem.audible]):.1f} dB of the models' causal Wiener filter")
    return FeedforwardDesign(StateSpaceFilter(*system), basis, c, achieved, full_db,
                             problem.attenuation(W, with_loop=True)[:nb] if with_loop else None, full_loop_db,
                             problem.audible.copy(), high, n, problem.grid.points, notes)
