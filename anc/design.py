"""Design a controller from the models: ``design(fb_model, ff_model, disturbance, options)``.

Order of the steps: (1) the uncertainty of S_model (``anc.uncertainty``); (2) the robust IMC
feedback filter Q and its bound (``anc.feedback.design_feedback``: the best Q of a rich family
under the amplification limit per band and r95 |G Q| <= 0.5, then balanced truncation);
(3) the feed-forward filter W for what the feedback leaves of the chin-coherent noise
(``anc.feedforward.design_feedforward``: Kautz bases with poles from the paths and the loop, the band rule,
balanced truncation); (4) the limits the paths allow for this noise at this latency
(``anc.limits.feedforward_limits``: causal Wiener feed-forward bound, coherence bound, what limits
each band) beside the feedback bound; (5) predictions per band (``anc.prediction``) for W alone, Q
alone and both, made with the filters as stored. Steps 2-4 take the noise as the models see it
(``Disturbance.modelled``), the predictions the recording's own chin-to-ear path: the FF model and what the
recording holds beyond it (``anc.disturbance``).

The criterion is the ear noise of the user's recording with ANC off (``anc.disturbance.from_recording``
with the FF model, ``helmet-anc design --disturbance``); without one, the documented default spectrum
(``anc.disturbance.default_disturbance``: wind and engine). The latency defaults to the board's control
path, ``BOARD_LATENCY_SAMPLES`` (2 samples, ``anc.controller``; ``codegen`` refuses less).

Refused: an FB model with a pole within ``UNDAMPED_MARGIN`` (1e-6) of the unit circle other than a
real one at DC (an identification defect; see the constant).

The controller records per band (``Controller.limits``) the causal feed-forward bound, the coherence
bound, the robust feedback bound (50 Hz-1 kHz) and in words what limits each; ``feedback_bound`` the
bound's own record; ``provenance["truncation"]`` the orders chosen.
"""

from __future__ import annotations

import re
import time
from dataclasses import asdict, dataclass

import numpy as np

from sysid.core import board
from sysid.core.errors import HelmetAncError
from sysid.core.model import Model
from sysid.estimation.input_nonlinearity import drive_limit

from .controller import BOARD_LATENCY_SAMPLES, Controller, StateSpaceFilter
from .disturbance import Disturbance, default_disturbance
from .feedback import ROBUSTNESS_BOUND, design_feedback, loop_margins
from .feedforward import BAND_TOLERANCE_DB, design_feedforward
from .limits import AMPLIFICATION_RANGE_DB, MAX_AMPLIFICATION_DB, MAX_GAIN_DB, RULES_PREFIX, feedforward_limits
from .prediction import (band_attenuation, band_centres, band_grid, coherence_bound, drive_psd, ear_psd,
                         overall_dba)
from .uncertainty import Uncertainty, model_uncertainty

__all__ = ["DesignOptions", "design", "predict", "band_limits", "board_cost", "UNDAMPED_MARGIN", "undamped_pole",
           "WEAK_DRIVE_DB", "scaled_filter", "BOARD_CYCLES_PER_SAMPLE", "INSTRUCTIONS_PER_SECTION", "PATH_INSTRUCTIONS"]

# An FB model pole closer than this to the unit circle (a mode decaying by 1/e in over 1e6 samples,
# 20 s at 48 kHz), other than a real pole at DC (Q's double zero), is refused: no acoustic path rings that long (the seed's FB path's slowest pole is
# 1 - 1e-4), and the runtime runs the internal model as given, so the loop d_hat = d + (S - S_model) y
# carries the model's resonance (random helmet 9: a pair at 22000.918 Hz with radius 1 - 1e-9 gives
# |S_model| = 2.5e8 there against |S| = 0.0075; closed-loop poles at radius 1.00003: unstable).
UNDAMPED_MARGIN = 1e-6
# A band where the drive path is this far below its loudest band is named as limited by the drive's
# weakness when neither coherence, a zero of S nor the chin path's lead explains its bound; nearer its
# peak nothing named explains it and nothing is said.
WEAK_DRIVE_DB = 20.0
# Peak over rms of the drive, a Gaussian noise: exceeded by 6e-5 of its samples.
DRIVE_CREST_FACTOR = 4.0

# The board's budget for the control path: half of a 168 MHz Cortex-M4 at 48 kHz (cycles per sample), and its
# cost from the emulated M4's measured figures (``sysid.core.board``: one Q15 step call per filter and sample, per
# section and per call) plus the path's own work (d_hat, delays, limiter): BENCHMARKS.md "Board control loop"
# measured 620 instructions a sample for S/Q/W of orders 7/22/22, whose three filter steps count 560. Instructions
# are not cycles (loads take 2), so the estimate is a lower bound.
BOARD_CYCLES_PER_SAMPLE = int(board.BOARD_CYCLES_PER_SAMPLE // 2)
INSTRUCTIONS_PER_SECTION = board.Q15_STEP_PER_SECTION
PATH_INSTRUCTIONS = 60


@dataclass(frozen=True)
class DesignOptions:
    """Design choices. ``latency`` in samples from measurement to drive (>= 1; default the board's control
    path, ``BOARD_LATENCY_SAMPLES``); ``max_amplification_db``: the amplification limit per band (dB) of Q, of W
    and of both (``anc.feedforward.allowed_ratio``);
    ``max_ff_gain_db``: W's gain bound outside the bands (dB); ``max_order``: the largest order of each
    filter (None: the order the design needs, cut to what the board affords when ``fit_board``: see
    ``board_orders``); ``drive_limit``: Q and W scaled so the drive's peaks stay within the FB model's
    drive limit (``drive_level``; a linear model has none)."""

    latency: int = BOARD_LATENCY_SAMPLES
    max_amplification_db: float = MAX_AMPLIFICATION_DB
    max_ff_gain_db: float = MAX_GAIN_DB
    feedback: bool = True
    feedforward: bool = True
    max_order: int | None = None
    fit_board: bool = True
    drive_limit: bool = True


def undamped_pole(model: Model) -> tuple[float, float] | None:
    """(radius, frequency in Hz) of the model's pole nearest the unit circle, leaving out real poles
    near z = 1, if it lies within ``UNDAMPED_MARGIN`` of it, else None. A pole at DC stays out of
    the loop: Q has a double zero there (``anc.feedback``), so |Delta Q| = 0 at DC whatever the model."""
    if not model.order:
        return None
    poles = np.linalg.eigvals(model.A)
    poles = poles[~((np.abs(poles.imag) < 1e-12) & (poles.real > 0.0))]
    if not poles.size:
        return None
    nearest = int(np.argmax(np.abs(poles)))
    radius = float(np.abs(poles[nearest]))
    if 1.0 - radius >= UNDAMPED_MARGIN:
        return None
    return radius, abs(float(np.angle(poles[nearest]))) * model.fs / (2.0 * np.pi)


def predict(s_model: Model, disturbance: Disturbance, latency: int, fb: StateSpaceFilter | None,
            ff: StateSpaceFilter | None) -> tuple[dict[str, list[float]], dict[str, float], list[float] | None]:
    """Per-band attenuation and overall dB(A) of W alone, Q alone and both, and the coherence bound."""
    fs = s_model.fs
    grid = band_grid()
    wide = np.geomspace(20.0, min(10000.0, 0.45 * fs), 2000)
    result, overall, bound = {}, {}, None
    for frequencies in (grid.reshape(-1), wide):
        G = s_model.frequency_response(frequencies) * np.exp(-2j * np.pi * frequencies * latency / fs)
        spectra = disturbance.at(frequencies)
        loop = None if fb is None else G * fb.frequency_response(frequencies, fs)
        gw = None if ff is None or not spectra.has_reference else G * ff.frequency_response(frequencies, fs)
        off = spectra.ear_psd
        on = {"ff": ear_psd(spectra, None, gw), "fb": ear_psd(spectra, loop, None), "both": ear_psd(spectra, loop, gw)}
        if frequencies is wide:
            overall = {part: overall_dba(frequencies, off, psd) for part, psd in on.items()}
        else:
            result = {part: band_attenuation(off.reshape(grid.shape), psd.reshape(grid.shape)) for part, psd in on.items()}
            bound = coherence_bound(spectra) if spectra.has_reference else None
    return result, overall, bound


def _ff_reason(text: str) -> str:
    """The feed-forward limit's reason as stored: a named cause as it is; the unexplained remainder
    ("regularisation: the drive path N dB below its peak, ...") only where the drive path is weak
    (``WEAK_DRIVE_DB``), else nothing (the bound there is not explained by any one cause); the bound within
    the design's rules (``anc.limits.RULES_CLAUSE``) kept wherever it is stated."""
    text, prefix, rules = text.partition(RULES_PREFIX)
    if text.startswith("regularisation"):
        found = re.search(r"drive path (-?[0-9.]+) dB below", text)
        below = float(found.group(1)) if found else 0.0
        text = f"the drive path {below:.0f} dB below its loudest band" if below >= WEAK_DRIVE_DB else ""
    if not rules:
        return text
    return text + prefix + rules if text else (prefix + rules).lstrip("; ")


def band_limits(bands_hz, ff_limits, fb_bound) -> dict:
    """Per band of ``bands_hz``: the causal feed-forward bound and the same within the design's rules, the
    coherence bound (None where silent or without a reference), the robust feedback bound (None outside its
    judged bands) and what limits each
    (``{"ff": [...], "fb": [...]}``, "" where nothing is named), all in dB, positive = quieter at the ear."""
    n = len(bands_hz)
    limits = {"bands_hz": [float(b) for b in bands_hz], "causal_ff_db": [None] * n, "causal_ff_ruled_db": [None] * n,
              "coherence_db": [None] * n, "feedback_db": [None] * n, "reasons": {"ff": [""] * n, "fb": [""] * n}}
    if ff_limits is not None:
        limits["causal_ff_db"] = list(ff_limits.causal_ff_db)
        limits["causal_ff_ruled_db"] = list(ff_limits.causal_ff_ruled_db or [None] * n)
        limits["coherence_db"] = list(ff_limits.coherence_db)
        limits["reasons"]["ff"] = [_ff_reason(r) for r in ff_limits.reasons]
        limits["latency_samples"] = int(ff_limits.latency_samples)
        limits["feedforward_details"] = ff_limits.details
    if fb_bound is not None:
        index = {round(float(b), 1): i for i, b in enumerate(bands_hz)}
        for b, value, reason in zip(fb_bound.bands_hz, fb_bound.attenuation_db,
                                    fb_bound.limits or [""] * len(fb_bound.bands_hz)):
            i = index.get(round(float(b), 1))
            if i is not None:
                limits["feedback_db"][i] = float(value)
                limits["reasons"]["fb"][i] = str(reason)
    return limits


def drive_level(s_model: Model, disturbance: Disturbance, fb: StateSpaceFilter | None,
                ff: StateSpaceFilter | None) -> dict:
    """The drive the controller asks of the driver (FS): its rms from ``prediction.drive_psd`` over 20 Hz to
    0.45 fs, its peaks at ``DRIVE_CREST_FACTOR`` times that, and the FB model's drive limit (the sine amplitude
    at which its input nonlinearity's harmonics reach -20 dB: ``sysid.estimation.input_nonlinearity.drive_limit``;
    None for a linear model). ``scale``: the factor on Q and W that keeps the peaks at the limit (1 within it)."""
    fs = s_model.fs
    frequencies = np.geomspace(20.0, 0.45 * fs, 4000)
    spectra = disturbance.at(frequencies)
    q = None if fb is None else fb.frequency_response(frequencies, fs)
    w = None if ff is None or not spectra.has_reference else ff.frequency_response(frequencies, fs)
    rms = float(np.sqrt(np.trapezoid(drive_psd(spectra, q, w), frequencies)))
    limit = drive_limit(s_model)
    peak = DRIVE_CREST_FACTOR * rms
    scale = 1.0 if limit is None or peak <= limit else limit / peak
    return {"rms_fs": rms, "peak_fs": peak, "limit_fs": limit, "scale": scale}


def scaled_filter(filt: StateSpaceFilter, scale: float) -> StateSpaceFilter:
    """The filter times ``scale`` (its output map and feed-through)."""
    return StateSpaceFilter(filt.A, filt.B, scale * filt.C, scale * filt.D)


def _within_drive_limit(scale: float, fb: StateSpaceFilter | None, ff: StateSpaceFilter | None, margins: dict,
                        fb_design) -> tuple:
    """Q and W times ``scale`` < 1, with the loop's margins of the scaled Q.

    The ear's response to the noise is affine in a common factor a on Q and W (e = a e_designed + (1 - a) e_off,
    the internal model taken exact), so every band lies between the design's level and no control's; robust
    stability holds a fortiori, the uncertainty disc r95 |G a Q| <= 0.5 shrinking with a."""
    fb = None if fb is None else scaled_filter(fb, scale)
    ff = None if ff is None else scaled_filter(ff, scale)
    if fb_design is not None:
        loop = scale * fb_design.loop
        margins = dict(fb_design.margins)
        margins.update(loop_margins(loop, fb_design.frequencies_hz, fb_design.relative_95, loop))
        if "robustness_factor_dense" in margins:
            margins["robustness_factor_dense"] /= scale
        margins = _margins(margins, loop)
    return fb, ff, margins


def _drive_note(drive: dict) -> str:
    """The controller's note on the drive against the FB model's drive limit."""
    text = (f"drive: {drive['rms_fs']:.3g} FS rms, peaks about {drive['peak_fs']:.3g} FS, against the FB model's "
            f"drive limit {drive['limit_fs']:.3g} FS (its input nonlinearity's harmonics at -20 dB)")
    if "applied_scale" in drive:
        return (text + f": Q and W scaled by {drive['applied_scale']:.3g} so the driver does not distort at this "
                "noise level (each band between the full design's level and no control's; --ignore-drive-limit "
                "keeps the full filters)")
    if drive["scale"] < 1.0:
        return (text + f": the driver would distort at this noise level; Q and W scaled by {drive['scale']:.3g} "
                "would keep it within, each band then between the controller's and no control's level")
    return text


def board_orders(s_order: int, q_order: int, w_order: int) -> tuple[int, int]:
    """The orders (Q, W) the board affords beside the internal model S: those given when the control path fits
    in ``BOARD_CYCLES_PER_SAMPLE``, else the sections left after S's shared 2 : 3 between Q and W (Q's
    truncation costs less per state: seed pair, Q at 60 states 0.8 dB below its 118, W at 120 states 1.4 dB
    below its 273), each no more than it needs; Q at least 4 states (its double zero at DC and a mode)."""
    if board_cost(s_order, q_order, w_order) <= BOARD_CYCLES_PER_SAMPLE:
        return q_order, w_order
    calls = 1 + (q_order > 0) + (w_order > 0)
    sections = int((BOARD_CYCLES_PER_SAMPLE - PATH_INSTRUCTIONS - calls * board.Q15_STEP_PER_CALL)
                   // INSTRUCTIONS_PER_SECTION) - board.sections(s_order)
    if w_order == 0:
        return min(q_order, 2 * max(sections, 2)), 0
    if q_order == 0:
        return 0, min(w_order, 2 * max(sections, 1))
    q = min(q_order, max(4, 2 * (2 * sections // 5)))
    return q, min(w_order, max(2, 2 * (sections - (q + 1) // 2)))


def board_cost(*orders: int) -> int:
    """Estimated instructions per sample of the board's control path running filters of these orders (the
    internal model S, Q, W): each filter's one-sample Q15 step (``sysid.core.board.board_cost``) plus the
    path's own ``PATH_INSTRUCTIONS``."""
    return int(round(PATH_INSTRUCTIONS + sum(board.board_cost(n).step for n in orders if int(n) > 0)))


def _loop_poles(fb_model: Model, fb: StateSpaceFilter | None, latency: int) -> np.ndarray | None:
    """The poles of G Q = z^-L S_model Q without S's delay (S's, Q's, the latency's), those of the target
    (1 + G Q) H that W cancels (``anc.feedforward_fit.path_poles``; S's delay as poles at the origin cost
    more under the board's cap than they hold); None without Q."""
    if fb is None:
        return None
    return np.concatenate([fb_model.poles() if fb_model.order else np.zeros(0, complex),
                           np.linalg.eigvals(fb.A) if fb.order else np.zeros(0, complex),
                           np.zeros(int(latency))])


def _margins(margins: dict, loop: np.ndarray) -> dict:
    """The loop's margins with the phase margin None where |Lg| never crosses 1 ("no crossover")."""
    Lg = -loop / (1.0 + loop)
    above = np.abs(Lg) > 1.0
    crossovers = int(np.count_nonzero(above[:-1] != above[1:]))
    margins = dict(margins)
    margins["crossovers"] = crossovers
    if not crossovers:
        margins["phase_margin_deg"] = None
    return margins


def design(fb_model: Model, ff_model: Model | None = None, disturbance: Disturbance | None = None,
           options: DesignOptions | None = None, uncertainty: Uncertainty | None = None,
           provenance: dict | None = None) -> Controller:
    """Controller for the FB model (S) and optionally the FF model (P); see the module docstring.

    ``disturbance`` defaults to ``default_disturbance(fs, ff_model)``; ``uncertainty`` to the
    FB model's own (``model_uncertainty``). Without a reference (no FF model and a disturbance
    without chin spectra) there is no W.
    """
    options = options or DesignOptions()
    started = time.process_time()
    if fb_model.path != "fb":
        raise HelmetAncError(f"the feedback model must be an FB model (drive -> ear); found path {fb_model.path!r}")
    if not fb_model.stable:
        raise HelmetAncError(f"the FB model is unstable (largest pole radius {fb_model.spectral_radius:.6f}); "
                             "identify or refine it again before designing a controller")
    undamped = undamped_pole(fb_model)
    if undamped is not None:
        radius, hz = undamped
        raise HelmetAncError(f"the FB model has an undamped pole at {hz:.0f} Hz (radius 1 - {1.0 - radius:.1e}; a mode "
                             f"ringing for over {1.0 / UNDAMPED_MARGIN:.0e} samples, which no acoustic path does): the "
                             "controller's internal model would keep it ringing; identify or refine the FB model again")
    if ff_model is not None:
        if ff_model.path != "ff":
            raise HelmetAncError(f"the feed-forward model must be an FF model (chin -> ear); found path {ff_model.path!r}")
        if ff_model.fs != fb_model.fs:
            raise HelmetAncError(f"FF model at {ff_model.fs:g} Hz, FB model at {fb_model.fs:g} Hz: identify both at one rate")
        if not ff_model.stable:
            raise HelmetAncError("the FF model is unstable; identify or refine it again before designing a controller")
    if not (isinstance(options.latency, (int, np.integer)) and not isinstance(options.latency, bool)
            and options.latency >= 1):
        raise HelmetAncError(f"latency must be a whole number of samples >= 1; found {options.latency!r}")
    low, high = AMPLIFICATION_RANGE_DB
    if isinstance(options.max_amplification_db, bool) or not (isinstance(options.max_amplification_db, (int, float))
                                                              and low < options.max_amplification_db <= high):
        raise HelmetAncError(f"max_amplification_db must be a number of dB above {low:g} and at most {high:g}; "
                             f"found {options.max_amplification_db!r}")
    if options.max_order is not None and not (isinstance(options.max_order, int) and options.max_order >= 3):
        raise HelmetAncError(f"max_order must be a whole number of states >= 3 (Q holds a double zero at DC and "
                             f"a mode) or None; found {options.max_order!r}")
    if ff_model is not None:
        model_uncertainty(ff_model)  # refuses an FF model whose error is unknown, as for the FB model
    disturbance = disturbance or default_disturbance(fb_model.fs, ff_model)
    # Designed on the noise as the models see it, predicted on the recording's own path (module docstring).
    modelled = disturbance.modelled()
    uncertainty = uncertainty or model_uncertainty(fb_model)
    order_budget = {} if options.max_order is None else {"max_order": options.max_order}
    notes: list[str] = []
    fb = ff = None
    truncation: dict[str, dict] = {}
    timing: dict[str, float] = {}
    margins: dict = {}
    loop_fn = None
    fb_bound = None
    fb_notes: list[str] = []  # the notes of the Q that is kept (it may be designed again at the board's cap)
    if options.feedback:
        t0 = time.process_time()
        fb_design = design_feedback(fb_model, modelled, options.latency, uncertainty,
                                    options.max_amplification_db, **order_budget)
        if options.max_order is None and options.fit_board:
            # Q alone on the board first; W, designed around Q's loop, is fitted to what Q leaves below.
            q_fits, _ = board_orders(fb_model.order, fb_design.filter.order, 0)
            if q_fits < fb_design.filter.order:
                fb_design = design_feedback(fb_model, modelled, options.latency, uncertainty,
                                            options.max_amplification_db, max_order=q_fits)
        timing["feedback"] = time.process_time() - t0
        fb, fb_bound = fb_design.filter, fb_design.bound
        margins = _margins(fb_design.margins, fb_design.loop)
        truncation["fb"] = dict(fb_design.reduction)
        fb_notes = list(fb_design.notes)

        def loop_fn(frequencies):
            Gf = fb_model.frequency_response(frequencies) * np.exp(-2j * np.pi * frequencies * options.latency / fb_model.fs)
            return Gf * fb.frequency_response(frequencies, fb_model.fs)

    ff_limits = None
    if disturbance.has_reference or ff_model is not None:
        t0 = time.process_time()
        ff_limits = feedforward_limits(fb_model, modelled, options.latency, ff_model=ff_model,
                                       max_amplification_db=options.max_amplification_db,
                                       max_gain_db=options.max_ff_gain_db)
        timing["limits"] = time.process_time() - t0
    if options.feedforward and disturbance.has_reference:
        t0 = time.process_time()
        ff_design = design_feedforward(fb_model, modelled, options.latency, uncertainty, feedback_loop=loop_fn,
                                       ff_model=ff_model, max_gain_db=options.max_ff_gain_db,
                                       max_amplification_db=options.max_amplification_db,
                                       loop_poles=_loop_poles(fb_model, fb, options.latency), **order_budget)
        if options.max_order is None and options.fit_board:
            q_order = 0 if fb is None else fb.order
            q_fits, w_fits = board_orders(fb_model.order, q_order, ff_design.filter.order)
            if q_fits < q_order:
                # Both do not fit: Q gets its share, W the rest, each designed again at its cap.
                fb_design = design_feedback(fb_model, modelled, options.latency, uncertainty,
                                            options.max_amplification_db, max_order=max(q_fits, 3))
                fb, fb_bound = fb_design.filter, fb_design.bound
                margins = _margins(fb_design.margins, fb_design.loop)
                truncation["fb"] = dict(fb_design.reduction)
                fb_notes = list(fb_design.notes)
            if w_fits < ff_design.filter.order or q_fits < q_order:
                ff_design = design_feedforward(fb_model, modelled, options.latency, uncertainty,
                                               feedback_loop=loop_fn, ff_model=ff_model,
                                               max_gain_db=options.max_ff_gain_db,
                                               max_amplification_db=options.max_amplification_db, max_order=w_fits,
                                               loop_poles=_loop_poles(fb_model, fb, options.latency))
        timing["feedforward"] = time.process_time() - t0
        ff = ff_design.filter
        truncation["ff"] = {"order": int(ff_design.order), "full_order": int(ff_design.full_order),
                            "kautz_functions": int(ff_design.basis.size - 1)}
        notes += ff_design.notes
    elif options.feedforward:
        notes.append("no feed-forward filter: no FF model and no chin-microphone spectrum")
    notes = fb_notes + notes
    cost = board_cost(fb_model.order, *(f.order for f in (fb, ff) if f is not None))
    fits = cost <= BOARD_CYCLES_PER_SAMPLE
    notes.append(f"board: the control path (S order {fb_model.order}, Q order {0 if fb is None else fb.order}, W order "
                 f"{0 if ff is None else ff.order}) is estimated at {cost} instructions per sample against "
                 f"{BOARD_CYCLES_PER_SAMPLE} cycles (half of a 168 MHz Cortex-M4 at 48 kHz)"
                 + ("" if fits else ": it does NOT fit; design again with DesignOptions(max_order=...) for the "
                    "order that fits, at the attenuation that costs"))
    drive = drive_level(fb_model, modelled, fb, ff)
    if drive["scale"] < 1.0 and options.drive_limit:
        fb, ff, margins = _within_drive_limit(drive["scale"], fb, ff, margins, fb_design if fb is not None else None)
        # The drive is linear in Q and W: its level scales with them (the peaks now at the limit).
        scale = drive["scale"]
        drive = dict(drive, rms_fs=scale * drive["rms_fs"], peak_fs=scale * drive["peak_fs"], scale=1.0,
                     applied_scale=scale)
    if drive["limit_fs"] is not None:
        notes.append(_drive_note(drive))
    predicted, overall, coherence = predict(fb_model, disturbance, options.latency, fb, ff)
    limits = band_limits(band_centres(), ff_limits, fb_bound)
    info = {
        "fb_model": fb_model.identification.get("noise_file") or fb_model.identification.get("source"),
        "ff_model": None if ff_model is None else (ff_model.identification.get("noise_file")
                                                   or ff_model.identification.get("source")),
        "disturbance": disturbance.source,
        "uncertainty": uncertainty.to_dict(),
        "options": asdict(options),
        "truncation": truncation,
        "feedforward_band_rule": {"limit_db": options.max_amplification_db, "tolerance_db": BAND_TOLERANCE_DB,
                                  "bands": "third-octave 20 Hz-2 kHz",
                                  "rule": "W makes no band with noise more than the limit louder than with ANC off, "
                                          "alone and with Q; where Q alone is already that loud, W adds at most the "
                                          "tolerance (predicted on the models)"},
        "robustness_bound": ROBUSTNESS_BOUND,
        "board": {"instructions_per_sample": cost, "budget_cycles_per_sample": BOARD_CYCLES_PER_SAMPLE,
                  "fits": fits},
        "drive": drive,
        "design_seconds_cpu": time.process_time() - started,
        "step_seconds_cpu": timing,
    }
    info.update(provenance or {})
    return Controller(fb_model.fs, fb_model, ff, fb, options.latency, band_centres(), predicted, margins, coherence,
                      overall, notes, info, limits=limits,
                      feedback_bound=None if fb_bound is None else fb_bound.to_dict())
