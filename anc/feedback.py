"""Feedback filter Q for internal model control: the bound's filter at an order the board runs.

With the runtime's observer d_hat = e - S_model y and y[k] = Q d_hat[k-L], a perfect model
gives e = (1 + G Q) d with G = z^-L S_model (the loop is open: d_hat = d); a model error
Delta = S - S_model closes a loop y = z^-L Q (d + Delta y), stable whenever |Delta Q| < 1 at
every frequency (small-gain theorem), which r95 |G Q| <= ``ROBUSTNESS_BOUND`` (0.5) keeps with
margin 2 for every path within the model's 95 % band.

``design_feedback``: (1) the bound (``anc.feedback_bound``: the best band-normalised ear power
of any Q of a rich family under the amplification limit per band and the robustness bound);
(2) the same program with the bounds tightened by ``DESIGN_MARGIN_DB`` and ``DESIGN_ROBUSTNESS``,
whose optimum leaves room for (3) balanced truncation (Moore 1981;
``sysid.core.lti.minimal_balanced_realisation``) of Q without its DC block to the lowest order
whose predicted attenuation in every judged band (third-octave 50 Hz-1 kHz) is within
``REDUCTION_TOLERANCE_DB`` of the full filter's and whose loop keeps both stated bounds on
``dense_grid`` (|1 + G Q| within the limit of every band 20 Hz-10 kHz, the edge bands' limits
beyond, and r95 |G Q| <= ``DENSE_MARGIN`` times the robustness bound); (4) the DC block in
series again, so Q keeps its double zero at DC at any order (below the identified band the path
is unknown: the seed's FB path has a pole at 0.9999 and 30 times its 20 Hz gain at DC). Under the
board's cap (``max_order``) the truncation ends at the cap, scaled to keep the bounds, and Q is also
designed again by step (2) in a basis that fits the cap, the better kept (seed: 1.5 / 0.8 / 0.3 dB
below the full filter at 40 / 60 / 100 states, against 3.0 / 2.4 dB truncated and scaled).
The design states where its loop amplifies (``amplification_db`` per band) and says so in its
notes for every band above 0 dB, naming the speech band.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from sysid.core.lti import minimal_balanced_realisation, state_responses
from sysid.core.model import Model
from sysid.core.structures import series

from .controller import StateSpaceFilter
from .disturbance import Disturbance
from .feedback_bound import (JUDGED_HZ, LIMIT_BANDS, ROBUSTNESS_BOUND, FeedbackBound, FeedbackFamily, FeedbackProblem,
                             amplification_limit, dense_grid, design_grid, feedback_bound, feedback_problem)
from .prediction import BANDS, band_attenuation, band_grid
from .uncertainty import Uncertainty

__all__ = ["FeedbackDesign", "design_feedback", "dense_grid", "design_grid", "loop_margins", "ROBUSTNESS_BOUND",
           "RMS_PER_95", "DESIGN_MARGIN_DB", "DESIGN_ROBUSTNESS", "DENSE_MARGIN", "REDUCTION_TOLERANCE_DB",
           "SPEECH_BAND_HZ"]

RMS_PER_95 = 1.0 / np.sqrt(np.log(20.0))
# The design's amplification limit lies this far below the stated one and its robustness bound at this
# fraction of the stated one: what the truncated filter may use of the stated bounds.
DESIGN_MARGIN_DB = 0.3
DESIGN_ROBUSTNESS = 0.9
# The stored filter keeps r95 |G Q| within this fraction of the bound on the dense grid (1 % for what lies
# between its points: a 4x finer grid found 0.07 % more than the dense grid on the seed).
DENSE_MARGIN = 0.99
REDUCTION_TOLERANCE_DB = 0.5
# Where a listener hears speech (telephone band): amplification there is named in the notes as such.
SPEECH_BAND_HZ = (300.0, 3400.0)


@dataclass
class FeedbackDesign:
    """The stored Q (``filter``: balanced, reduced, double zero at DC) and what it does on the model.

    ``predicted_db``: attenuation per band of ``anc.prediction.BANDS`` (third-octave 20 Hz-2 kHz), as
    ``anc.design.predict`` computes it; ``amplification_db``: the largest 20 log10 |1 + G Q| per band of
    ``LIMIT_BANDS`` (20 Hz-10 kHz) on the dense grid, against ``amplification_limit_db``; the loop G Q
    on ``frequencies_hz`` (``design_grid``); ``bound``: the feedback bound; ``reduction``: orders and
    the largest band change of the truncation; ``margins`` and ``notes`` (why it is as it is)."""

    filter: StateSpaceFilter
    bound: FeedbackBound
    predicted_db: np.ndarray
    amplification_db: np.ndarray
    amplification_limit_db: np.ndarray
    frequencies_hz: np.ndarray
    loop: np.ndarray
    relative_95: np.ndarray
    reduction: dict = field(default_factory=dict)
    margins: dict = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def sensitivity(self) -> np.ndarray:
        """1 + G Q on ``frequencies_hz``: ear noise with control over ear noise without (nominal model)."""
        return 1.0 + self.loop


def loop_margins(loop: np.ndarray, frequencies_hz: np.ndarray, relative_95: np.ndarray, s_model_q: np.ndarray) -> dict:
    """Margins of the equivalent one-degree-of-freedom loop and the robustness figures.

    The IMC law equals the feedback controller K = z^-L Q / (1 + z^-L Q S_model) on e;
    its loop gain (negative-feedback convention, e = d / (1 + Lg)) is
    Lg = -S K = -G Q / (1 + G Q) on the nominal model. Gain margin: 1/|Lg| where Lg crosses
    the negative real axis (inf if never); phase margin: 180 deg + arg Lg where |Lg| = 1
    (180 if never); peak amplification: max 20 log10 |1 + G Q|; robustness factor:
    min 0.5 / (r_95 |S_model Q|) (> 1: the stated uncertainty is met with margin).
    """
    Lg = -loop / (1.0 + loop)
    gm = np.inf
    crossing = np.nonzero((np.sign(Lg.imag[:-1]) != np.sign(Lg.imag[1:])) & (Lg.real[:-1] < 0))[0]
    for i in crossing:
        t = Lg.imag[i] / (Lg.imag[i] - Lg.imag[i + 1])
        value = Lg[i] + t * (Lg[i + 1] - Lg[i])
        if value.real < 0:
            gm = min(gm, 1.0 / abs(value.real))
    pm = 180.0
    magnitude = np.abs(Lg)
    for i in np.nonzero(np.sign(magnitude[:-1] - 1.0) != np.sign(magnitude[1:] - 1.0))[0]:
        pm = min(pm, 180.0 - abs(np.degrees(np.angle(Lg[i]))))
    amplification = 20.0 * np.log10(np.abs(1.0 + loop))
    peak = int(np.argmax(amplification))
    usage = relative_95 * np.abs(s_model_q)
    return {
        "gain_margin_db": float(20.0 * np.log10(gm)) if np.isfinite(gm) else None,
        "phase_margin_deg": float(pm),
        "peak_amplification_db": float(amplification[peak]),
        "peak_amplification_hz": float(frequencies_hz[peak]),
        "robustness_factor": float(ROBUSTNESS_BOUND / max(np.max(usage), 1e-300)),
    }


def _dc_block(family) -> tuple:
    """(A, B, C, D) of the family's DC block H (``anc.feedback_bound.FeedbackFamily``)."""
    b = family.highpass_pole
    g = ((1.0 + b) / 2.0) ** 2
    return (np.array([[2.0 * b, -b * b], [1.0, 0.0]]), np.array([[1.0], [0.0]]),
            g * np.array([[2.0 * b - 2.0, 1.0 - b * b]]), np.array([[g]]))


def _reduced(problem: FeedbackProblem, coefficients: np.ndarray, limit_dense: np.ndarray,
             robustness_bound: float, max_order: int | None = None) -> tuple[StateSpaceFilter, dict]:
    """The lowest-order truncation of Q that keeps the judged bands and the bounds (module docstring),
    balanced once more with its DC block; under ``max_order`` (Q's states with the DC block's two) the
    search ends at the cap, and a truncation there that breaks a bound is scaled (t Q, 0 < t <= 1) to the
    largest t that keeps both (|1 + t G Q| <= (1 - t) + t |1 + G Q|, so a small enough t always does).

    Each order is judged on its responses by ``sysid.core.lti.state_responses`` (O(n^2) per point) and the
    orders are searched by doubling, then bisection between the last two (the judged change shrinks with
    the order, not strictly; the order found keeps the bounds, a lower one might too)."""
    family = problem.family
    fs = family.outer.fs
    balanced = minimal_balanced_realisation(*series(family.basis.statespace(coefficients),
                                                    family.outer.inverse_statespace()))
    full_order = balanced.A.shape[0]
    f_obj = problem.objective_hz.reshape(-1)
    highpass = _dc_block(family)
    z_obj = np.exp(2j * np.pi * f_obj / fs)
    z_dense = np.exp(2j * np.pi * problem.dense_hz / fs)
    block_obj = family._highpass(f_obj)
    block_dense = family._highpass(problem.dense_hz)
    D = float(np.asarray(balanced.D).reshape(-1)[0])

    def response(order: int, z: np.ndarray, block: np.ndarray) -> np.ndarray:
        # Balanced truncation: the leading block of the balanced realisation (Moore 1981), then the DC block.
        A, B, C = balanced.A[:order, :order], balanced.B[:order], balanced.C[:, :order]
        part = C[0] @ state_responses(A, B, z) + D if order else np.full(z.size, D, dtype=complex)
        return part * block

    def judged_db(order: int, scale: float = 1.0) -> np.ndarray:
        return -10.0 * np.log10(problem.band_ratios(problem.objective_g * scale * response(order, z_obj, block_obj)))

    reference = judged_db(full_order)
    radius = DENSE_MARGIN * robustness_bound / np.maximum(problem.relative_95, 1e-300)

    def keeps_bounds(loop: np.ndarray) -> bool:
        return bool(np.all(np.abs(1.0 + loop) <= limit_dense) and np.all(np.abs(loop) <= radius))

    def acceptable(order: int) -> bool:
        if np.max(np.abs(judged_db(order) - reference)) > REDUCTION_TOLERANCE_DB:
            return False
        if order and np.max(np.abs(np.linalg.eigvals(balanced.A[:order, :order]))) >= 1.0:
            return False
        return keeps_bounds(problem.dense_g * response(order, z_dense, block_dense))

    top = full_order if max_order is None else max(0, min(full_order, int(max_order) - 2))
    high = 1
    while high < top and not acceptable(high):
        high *= 2
    high = min(high, top)
    low = high // 2
    while high - low > 1:
        middle = (low + high) // 2
        if acceptable(middle):
            high = middle
        else:
            low = middle
    chosen, scale = high, 1.0
    capped = chosen < full_order and not acceptable(chosen)
    if capped:
        stable = chosen == 0 or np.max(np.abs(np.linalg.eigvals(balanced.A[:chosen, :chosen]))) < 1.0
        loop = problem.dense_g * response(chosen, z_dense, block_dense)
        scale = 0.0
        if stable:
            lo, hi = 0.0, 1.0
            for _ in range(30):
                t = (lo + hi) / 2.0
                lo, hi = (t, hi) if keeps_bounds(t * loop) else (lo, t)
            scale = lo
    whole = minimal_balanced_realisation(*series(
        (balanced.A[:chosen, :chosen], balanced.B[:chosen], scale * balanced.C[:, :chosen],
         np.array([[scale * D]])), highpass))
    q = StateSpaceFilter(whole.A, whole.B, whole.C, np.array([[whole.D]]))
    change = judged_db(chosen, scale) - reference
    judged = (problem.bands_hz >= JUDGED_HZ[0]) & (problem.bands_hz <= JUDGED_HZ[1])
    return q, {"order": q.order, "full_order": full_order + 2,
               "max_band_change_db": float(np.max(np.abs(change))) if chosen < full_order else 0.0,
               "tolerance_db": REDUCTION_TOLERANCE_DB, "capped": bool(capped), "scale": float(scale),
               "cap_cost_db": float(-np.mean(change[judged])) if capped else 0.0}


def _designed_at_cap(problem: FeedbackProblem, s_model: Model, disturbance: Disturbance, latency: int,
                     uncertainty: Uncertainty, max_amplification_db, max_order: int, limit_dense: np.ndarray,
                     full_coefficients: np.ndarray) -> tuple[StateSpaceFilter, dict] | None:
    """Q designed by the same program in a basis small enough that Q with S_o^-1 and its DC block has at most
    ``max_order`` states (None when the outer factor alone fills the cap), scaled like a truncation if its
    stored filter breaks a bound between the program's points; the reduction record of ``_reduced``."""
    family = problem.family
    outer_states = family.outer.inverse_statespace()[0].shape[0]
    size = int(max_order) - 2 - outer_states
    if size < 1:
        return None
    small = FeedbackFamily.of(s_model, size=size)
    base = feedback_problem(s_model, disturbance, latency, uncertainty, max_amplification_db,
                            problem.robustness_bound, small)
    tight = FeedbackProblem(**{**base.__dict__, "limit": base.limit * 10.0 ** (-DESIGN_MARGIN_DB / 20.0),
                               "robustness_bound": DESIGN_ROBUSTNESS * base.robustness_bound})
    c = tight.solve()
    fs = family.outer.fs
    f_obj = problem.objective_hz.reshape(-1)
    loop = base.dense_g * (base.dense_q @ c)
    radius = DENSE_MARGIN * problem.robustness_bound / np.maximum(base.relative_95, 1e-300)
    lo, hi = 0.0, 1.0
    if np.all(np.abs(1.0 + loop) <= limit_dense) and np.all(np.abs(loop) <= radius):
        lo = 1.0
    else:
        for _ in range(30):
            t = (lo + hi) / 2.0
            keeps = np.all(np.abs(1.0 + t * loop) <= limit_dense) and np.all(np.abs(t * loop) <= radius)
            lo, hi = (t, hi) if keeps else (lo, t)
    whole = minimal_balanced_realisation(*small.statespace(lo * c))
    q = StateSpaceFilter(whole.A, whole.B, whole.C, np.array([[whole.D]]))
    if q.order > max_order or (q.order and np.max(np.abs(np.linalg.eigvals(q.A))) >= 1.0):
        return None
    full = problem.objective_g * (problem.objective_q @ full_coefficients)
    reference = -10.0 * np.log10(problem.band_ratios(full))
    change = -10.0 * np.log10(problem.band_ratios(problem.objective_g * q.frequency_response(f_obj, fs))) - reference
    judged = (problem.bands_hz >= JUDGED_HZ[0]) & (problem.bands_hz <= JUDGED_HZ[1])
    return q, {"order": q.order, "full_order": None,
               "max_band_change_db": float(np.max(np.abs(change))), "tolerance_db": REDUCTION_TOLERANCE_DB,
               "capped": True, "scale": float(lo), "cap_cost_db": float(-np.mean(change[judged])),
               "basis_size": size}


def _band_peaks(frequencies_hz: np.ndarray, amplification_db: np.ndarray) -> np.ndarray:
    """The largest value of amplification_db inside each band of ``LIMIT_BANDS`` (the edge bands reaching to
    DC and to fs / 2, as their limits do)."""
    edges = np.array([hi for _, _, hi in LIMIT_BANDS[:-1]])
    band = np.searchsorted(edges, frequencies_hz, side="right")
    peaks = np.full(len(LIMIT_BANDS), -np.inf)
    np.maximum.at(peaks, band, amplification_db)
    return peaks


def _amplification_notes(amplification_db: np.ndarray, limit_db: np.ndarray) -> list[str]:
    """Where the loop amplifies (above 0 dB), per band of ``LIMIT_BANDS``, the speech band named."""
    louder = [(centre, a, lim) for (centre, _, _), a, lim in zip(LIMIT_BANDS, amplification_db, limit_db) if a > 0.0]
    if not louder:
        return ["Q amplifies in no band 20 Hz-10 kHz (|1 + G Q| <= 1 on the model)"]
    speech = [(c, a) for c, a, _ in louder if SPEECH_BAND_HZ[0] <= c <= SPEECH_BAND_HZ[1]]
    listed = ", ".join(f"{c:g} Hz +{a:.1f} dB (limit {lim:g})" for c, a, lim in louder)
    notes = [f"Q amplifies (the waterbed: Bode's sensitivity integral) by at most the stated limit per band, "
             f"at {listed}"]
    if speech:
        notes.append(f"of which in the speech band {SPEECH_BAND_HZ[0]:g}-{SPEECH_BAND_HZ[1]:g} Hz: "
                     + ", ".join(f"{c:g} Hz +{a:.1f} dB" for c, a in speech)
                     + "; lower the limit of those bands (max_amplification_db per band) to move it elsewhere")
    return notes


def design_feedback(s_model: Model, disturbance: Disturbance, latency: int, uncertainty: Uncertainty,
                    max_amplification_db=6.0, robustness_bound: float = ROBUSTNESS_BOUND,
                    explain: bool = True, max_order: int | None = None) -> FeedbackDesign:
    """Robust IMC feedback filter Q for the model (module docstring) and its bound.

    ``disturbance``: the ear noise with ANC off (its ear spectrum is the criterion's weight within each
    band); ``latency`` in samples; ``max_amplification_db``: one number or one per band of
    ``anc.feedback_bound.LIMIT_BANDS`` (third-octave 20 Hz-10 kHz); ``explain``: measure what limits
    each band of the bound (``anc.feedback_bound.feedback_bound``); ``max_order``: Q's states at most, its
    DC block's two included (the board's budget; None: the lowest order within ``REDUCTION_TOLERANCE_DB``),
    what the cap costs stated in the notes (mean 50 Hz-1 kHz).

    One BLAS thread: the matrices are of a few hundred rows, where threads on a busy machine multiply the CPU
    time (``anc.disc_program``).
    """
    if max_order is not None and int(max_order) < 3:
        raise ValueError(f"max_order must leave Q a state beside its DC block's two; found {max_order}")
    with threadpool_limits(limits=1, user_api="blas"):
        return _design(s_model, disturbance, latency, uncertainty, max_amplification_db, robustness_bound, explain,
                       max_order)


def _design(s_model, disturbance, latency, uncertainty, max_amplification_db, robustness_bound, explain,
            max_order) -> FeedbackDesign:
    fs = s_model.fs
    problem = feedback_problem(s_model, disturbance, latency, uncertainty, max_amplification_db, robustness_bound)
    bound = feedback_bound(s_model, disturbance, latency, uncertainty, max_amplification_db, robustness_bound,
                           explain, problem)
    limit_dense = problem.limit
    tight = problem.limit * 10.0 ** (-DESIGN_MARGIN_DB / 20.0)
    design_problem = FeedbackProblem(**{**problem.__dict__, "limit": tight,
                                        "robustness_bound": DESIGN_ROBUSTNESS * problem.robustness_bound})
    coefficients = design_problem.solve(start=bound.coefficients)
    q, reduction = _reduced(problem, coefficients, limit_dense, problem.robustness_bound, max_order)
    notes = []
    if reduction["capped"]:
        smaller = _designed_at_cap(problem, s_model, disturbance, latency, uncertainty, max_amplification_db,
                                   max_order, limit_dense, coefficients)
        if smaller is not None and smaller[1]["cap_cost_db"] < reduction["cap_cost_db"]:
            q, reduction = smaller[0], {**smaller[1], "full_order": reduction["full_order"]}
            notes.append(f"Q at the cap: designed again in a basis of {reduction['basis_size']} functions (the "
                         "truncated full filter lost more)")
    if reduction["capped"]:
        scaled = f", scaled by {reduction['scale']:.3f} to keep the bounds" if reduction["scale"] < 1.0 else ""
        notes.append(f"Q capped at {reduction['order']} states (max_order; full order {reduction['full_order']})"
                     f"{scaled}: {reduction['cap_cost_db']:.2f} dB below "
                     f"the full filter's mean over the judged bands {JUDGED_HZ[0]:g} Hz-{JUDGED_HZ[1] / 1000:g} kHz")
    elif reduction["order"] == reduction["full_order"]:
        notes.append(f"Q kept at its full order {reduction['order']}: no truncation kept the judged bands within "
                     f"{REDUCTION_TOLERANCE_DB} dB and the bounds")
    else:
        notes.append(f"Q truncated from order {reduction['full_order']} to {reduction['order']} (balanced "
                     f"truncation): judged bands within {reduction['max_band_change_db']:.2f} dB of the full filter's")
    # Predictions as anc.design.predict makes them, on the stored filter.
    grid = band_grid()
    f = grid.reshape(-1)
    G = s_model.frequency_response(f) * np.exp(-2j * np.pi * f * latency / fs)
    off = np.maximum(disturbance.at(f).ear_psd, 0.0)
    on = np.abs(1.0 + G * q.frequency_response(f, fs)) ** 2 * off
    predicted = np.array(band_attenuation(off.reshape(grid.shape), on.reshape(grid.shape)))
    dense_loop = problem.dense_g * q.frequency_response(problem.dense_hz, fs)
    amplification = _band_peaks(problem.dense_hz, 20.0 * np.log10(np.abs(1.0 + dense_loop)))
    limit_db = amplification_limit([c for c, _, _ in LIMIT_BANDS], max_amplification_db)
    notes += _amplification_notes(amplification, limit_db)
    f_design = design_grid(fs)
    loop = s_model.frequency_response(f_design) * np.exp(-2j * np.pi * f_design * latency / fs) \
        * q.frequency_response(f_design, fs)
    r95 = uncertainty.at(f_design)
    margins = loop_margins(loop, f_design, r95, loop)
    usage = problem.relative_95 * np.abs(dense_loop)
    margins.update({"robustness_factor_dense": float(problem.robustness_bound / max(float(usage.max()), 1e-300)),
                    "robustness_worst_hz": float(problem.dense_hz[int(np.argmax(usage))]),
                    "robustness_points": int(problem.dense_hz.size)})
    judged = np.array([BANDS.index(b) for b in BANDS if b[0] in set(bound.bands_hz)])
    notes.append(f"feedback bound {bound.mean_db:.1f} dB (mean over the third-octave bands 50 Hz-1 kHz; "
                 f"{DESIGN_MARGIN_DB} dB and {1 - DESIGN_ROBUSTNESS:.0%} inside its bounds, the design predicts "
                 f"{float(np.mean(predicted[judged])):.1f} dB)")
    return FeedbackDesign(q, bound, predicted, amplification, limit_db, f_design, loop, r95, reduction, margins, notes)
