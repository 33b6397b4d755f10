"""A reverberant tail: the path rings longer, on denser modes, than the model's states hold (effects.md).

Measured acoustic paths (a headphone on an ear, a helmet liner, a head in a room) keep ringing
for tens of milliseconds above a good microphone's noise: reflections inside the shell and off
the head and torso, dense high-order cavity modes. A model capped at a few tens of states holds
the direct sound and the strongest modes; the rest of the ringing is its error, spread over many
narrow bands, and more states lower it slowly (each adds about one mode).

What the detector reads (the shared value ``long-response``, computed once per diagnosis):

1. The noise recording's impulse response behind the model's delay and input polynomial: the
   least-squares FIR (``sysid.estimation.long_response.fir_estimate``), ``TAIL_FIRST_S`` long,
   doubled (at most ``TAIL_DOUBLINGS`` times) while the response is still above its noise in the
   estimate's last quarter; the model's own impulse response beside it.
2. Their band-limited power envelopes (``band_envelope``): the taps through a Kaiser low-pass from
   the validation band's top to the identification band's (the taps above it are the input
   roll-off's amplified noise), squared and averaged over ``TAIL_ENVELOPE_S``. The noise's
   envelope is the estimate's in-band noise per tap (Ljung, "System Identification", 2nd ed.,
   sec. 9.2: ``FirEstimate.noise_rms``) weighted by the low-pass (``noise_rms``).
3. The response's length: the time until its envelope stays less than ``TAIL_ABOVE_NOISE_DB``
   above the noise's (``length_above_noise``), counted from the input, the delay included.
4. The tail, once the direct sound has fallen ``TAIL_DIRECT_DB`` below the envelope's peak: its
   level (mean power re the peak, dB), its decay rate (the slope of the envelope in dB over the
   tail, dB/ms; the reverberation time T60 is 60 dB over it) and the band holding the central
   80 % of its energy.
5. The states it needs (``truncation_ladder``): the FIR's frequency-limited balanced truncation
   (Gawronski & Juang 1990, ``frequency_limited_truncation``) at orders doubling from the model's,
   each validated on the sweeps, then bisected to the lowest order at the floor (``AT_FLOOR``, or
   just above the FIR's own validation error when the estimate cannot get there, or just above
   the error where twice and four times the states buy next to nothing: the states that pay). Output error
   beats truncation at equal order, so this is what the data need at most, and the ladder tells
   what more states would buy.

The tail is the finding when it explains the error: the truncation at the order it needs
validates ``EXPLAINS_GAIN`` better than the model and removes ``FACTOR_SHARE`` of the error power
above the floor (as a series factor must), that order is ``TAIL_STATES_RATIO`` times the model's
and ``TAIL_MIN_EXTRA_STATES`` more (dense modes, not a few missing ones: that is under-modelled),
the model's order counted as the truncation's that validates as well as it (output error holds
a response in fewer states than truncation: a 5-state helmet path's truncation needs 15), and no
named effect but a delay explains the error first. ``refine`` adds it by the same ladder
on the model's corrected data (``sysid.refits.long_estimate``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal

from ..core import lti
from ..core.model import MAX_ORDER, Model
from ..core.thresholds import (AT_FLOOR, EXCESS, EXPLAINS_GAIN, FACTOR_SHARE, IDENTIFICATION_BAND, NEGLIGIBLE_HSV,
                               TAIL_ABOVE_NOISE_DB, TAIL_DIRECT_DB, TAIL_ENVELOPE_S, TAIL_DOUBLINGS, TAIL_FIRST_S,
                               TAIL_LADDER_SLACK, TAIL_MIN_EXTRA_STATES, TAIL_STATES_RATIO, VALIDATION_BAND)
from ..estimation.long_response import FirEstimate, fir_estimate, frequency_limited_truncation
from ..io.recordings import Recording
from ..validation.sweeps import CompressedValidation, SweepSpectrum, rms_from_responses, sweep_spectrum
from . import DiagnosisContext, finding, provider, uses

__all__ = ["LongResponse", "TruncationLadder", "band_envelope", "noise_rms", "length_above_noise", "long_response",
           "tail_spectra", "estimate_ratio", "truncation_ladder", "ladder_text", "tail_finding"]

NO_IN_BAND_ERROR = ("dc-offset", "time-variation")
# The envelope's low-pass: flat to the validation band's top, TAIL_STOPBAND_DB down from the identification band's.
TAIL_STOPBAND_DB = 120.0
# Compressed validation cells (Hz) of the ladder's orders; the bisection ends within LADDER_RESOLUTION of the
# lowest order at the target (about 330 states or 340 tell the user the same; each order costs a realisation).
LADDER_CELL_HZ = 2.0
LADDER_RESOLUTION = 0.05


def _kernel(fs: float) -> np.ndarray:
    """The envelope's zero-phase low-pass (Kaiser window design: Oppenheim & Schafer, 3rd ed., sec. 7.6)."""
    low, high = VALIDATION_BAND[1], min(IDENTIFICATION_BAND[1], 0.45 * fs)
    low = min(low, 0.8 * high)
    numtaps, beta = scipy.signal.kaiserord(TAIL_STOPBAND_DB, (high - low) / (fs / 2))
    return scipy.signal.firwin(numtaps | 1, (low + high) / 2, window=("kaiser", beta), fs=fs)


def _smoothed(taps: np.ndarray, fs: float) -> np.ndarray:
    """The taps through the envelope's low-pass, aligned (zero phase)."""
    h = _kernel(fs)
    return scipy.signal.oaconvolve(taps, h)[h.size // 2: h.size // 2 + taps.size]


def band_envelope(taps: np.ndarray, fs: float) -> np.ndarray:
    """Power envelope (FS^2 per tap) of an impulse response in the validation band: the taps low-passed,
    squared and averaged over ``TAIL_ENVELOPE_S`` (centred)."""
    window = max(1, int(round(TAIL_ENVELOPE_S * fs)))
    return np.convolve(_smoothed(np.asarray(taps, dtype=float), fs) ** 2, np.ones(window) / window, mode="same")


def noise_rms(estimate: FirEstimate) -> float:
    """RMS per tap (FS per FS) of the estimate's noise through the envelope's low-pass: the per-bin noise
    variance (``FirEstimate.noise_rms`` on each bin of its input spectrum) weighted by the low-pass's |H|^2."""
    bins = estimate.input_psd.size
    f = np.linspace(0.0, estimate.fs / 2, bins)
    gain = np.abs(np.fft.rfft(_kernel(estimate.fs), 2 * (bins - 1)))
    step = f[1] - f[0]
    # The bins the low-pass passes at all; above them the taps' noise is the input roll-off's, held off by it.
    passed = np.flatnonzero(gain > 10 ** (-TAIL_STOPBAND_DB / 40))
    variance = sum(gain[k] ** 2 * estimate.noise_rms((f[k] - step / 2, f[k] + step / 2)) ** 2 for k in passed)
    return float(np.sqrt(variance))


def length_above_noise(envelope: np.ndarray, noise: float, fs: float) -> float:
    """Seconds until ``envelope`` (``band_envelope``) stays less than ``TAIL_ABOVE_NOISE_DB`` above the power
    ``noise**2`` of the estimate's noise: the envelope of response plus noise, less the noise's, against
    the threshold (0 when it never rises above)."""
    excess = envelope - noise**2
    above = np.flatnonzero(excess > 10 ** (TAIL_ABOVE_NOISE_DB / 10) * noise**2)
    return float(above[-1] + 1) / fs if above.size else 0.0


@dataclass(frozen=True)
class LongResponse:
    """The noise recording's long impulse response against the model's (the shared value ``long-response``).

    ``taps``: the least-squares FIR behind the model's delay (FS per FS, at ``fs``); ``model_taps``: the
    model's core over as many taps; ``noise``: the estimate's noise per tap in the validation band;
    ``envelope``, ``model_envelope``, ``residual_envelope``: their band-limited power envelopes
    (``band_envelope``; FS^2 per tap); ``length_s``, ``model_length_s``, ``residual_length_s``: how long
    each stays above the noise, from the input (delay included); ``complete``: the data's response fell
    below its noise inside the estimate (otherwise ``length_s`` is a lower bound).
    """

    fs: float
    delay: int
    estimate: FirEstimate
    taps: np.ndarray
    model_taps: np.ndarray
    noise: float
    envelope: np.ndarray
    model_envelope: np.ndarray
    residual_envelope: np.ndarray
    length_s: float
    model_length_s: float
    residual_length_s: float
    complete: bool

    @property
    def times_s(self) -> np.ndarray:
        """Time of each tap from the input (s), delay included."""
        return (self.delay + np.arange(self.taps.size)) / self.fs


def _core_input(model, u: np.ndarray) -> np.ndarray:
    """The model's input map: its polynomial, then its delay."""
    v = model.apply_input_nonlinearity(u)
    d = min(model.delay, v.size)
    return np.concatenate((np.zeros(d), v[: v.size - d]))


def long_response(model, noise: Recording, transient_s: float) -> LongResponse:
    """The ``LongResponse`` of ``model`` on a noise recording (the ear signal less the model's output offset)."""
    fs = noise.fs
    v, y = _core_input(model, noise.u), noise.y - model.output_offset
    start = int(round(transient_s * fs))
    length = int(round(TAIL_FIRST_S * fs))
    for doubling in range(TAIL_DOUBLINGS + 1):
        estimate = fir_estimate(v, y, fs, length, start)
        noise_level = noise_rms(estimate)
        envelope = band_envelope(estimate.taps, fs)
        above = length_above_noise(envelope, noise_level, fs)
        # Doubled while the response still rings in the estimate's last quarter and the data hold a longer one.
        complete = above < 0.75 * length / fs
        if complete or doubling == TAIL_DOUBLINGS or y.size - start < 8 * length or start < 4 * length - 1:
            break
        length *= 2
    impulse = np.zeros(length)
    impulse[0] = 1.0
    model_taps = lti.simulate(model.A, model.B, model.C, model.D, impulse)
    model_envelope = band_envelope(model_taps, fs)
    residual_envelope = band_envelope(estimate.taps - model_taps, fs)
    offset = model.delay / fs
    return LongResponse(fs, model.delay, estimate, estimate.taps, model_taps, noise_level, envelope, model_envelope,
                        residual_envelope, above + offset, length_above_noise(model_envelope, noise_level, fs) + offset,
                        length_above_noise(residual_envelope, noise_level, fs) + offset, complete)


@provider("long-response")
def _long_response(ctx: DiagnosisContext) -> LongResponse:
    return long_response(ctx.model, ctx.noise, ctx.transient_s)


def tail_spectra(model, sweeps: list[Recording], comparison) -> list[SweepSpectrum]:
    """The sweeps' DFT bins in the validation band, input through the model's polynomial (its delay left to the
    responses), ear signal without the model's disturbance lines and output offset (``comparison``'s)."""
    spectra = []
    for sweep, entry in zip(sweeps, comparison.per_sweep):
        measured = sweep.y - (entry["predicted"] - entry["linear"])
        spectra.append(sweep_spectrum(Recording(model.apply_input_nonlinearity(sweep.u), measured, sweep.fs,
                                                sweep.path)))
    return spectra


def estimate_ratio(ctx: DiagnosisContext, delay: int) -> float:
    """Validation error (rms over the noise floor, on the sweeps' DFT bins) of the noise recording's long
    least-squares FIR behind ``delay`` samples (the model's input map otherwise): what any model behind that
    delay can reach. At the model's own delay it is the shared ``long-response``'s estimate."""
    model = ctx.model
    if delay == model.delay:
        taps = ctx.value("long-response").taps
    else:
        taps = long_response(_at_delay(model, delay), ctx.noise, ctx.transient_s).taps
    spectra = tail_spectra(model, ctx.sweeps, ctx.comparison)
    responses = [np.polyval(taps[::-1], np.exp(-2j * np.pi * s.frequencies / ctx.fs))
                 * np.exp(-2j * np.pi * s.frequencies * delay / ctx.fs) for s in spectra]
    return rms_from_responses(spectra, responses) / ctx.comparison.noise_floor


def _response(system, z: np.ndarray) -> np.ndarray:
    """G(z) of a high-order system: by its modal form when that is well conditioned, else by its complex Schur
    form, one back substitution vectorised over the points (n^2 per point, no n x n system per point)."""
    A, B, C, D = lti.as_siso(*system)
    modal = lti.modal_form(A, B, C, D)
    if modal.reliable:
        return lti.pole_residue_response(modal.poles, modal.residues, D, z)
    T, Z = scipy.linalg.schur(A.astype(complex), output="complex")
    b, c = Z.conj().T @ B[:, 0], C[0] @ Z
    n = A.shape[0]
    x = np.zeros((n, z.size), dtype=complex)
    for i in range(n - 1, -1, -1):
        x[i] = (b[i] + T[i, i + 1:] @ x[i + 1:]) / (z - T[i, i])
    return c @ x + D


@dataclass(frozen=True)
class TruncationLadder:
    """Validation error (rms over the noise floor) of a long FIR's truncations at the orders tried.

    ``orders``/``ratios`` ascending in order; ``needed``: the lowest order within ``target`` (None when
    none is); ``best``: the order of lowest ratio; ``fir_ratio``: the FIR's own; ``model_ratio``: the model's
    by the same reckoning (the sweeps' DFT bins); ``model_states``: the lowest order that validates as well as
    the model, within ``TAIL_LADDER_SLACK`` (the model's order in truncation's currency: output error holds a
    response in fewer states, 3x fewer on a 5-state helmet path); ``truncation``: every order's realisation.
    """

    orders: tuple[int, ...]
    ratios: tuple[float, ...]
    needed: int | None
    best: int
    target: float
    fir_ratio: float
    model_ratio: float
    model_states: int | None
    truncation: object

    def ratio(self, order: int) -> float:
        return self.ratios[self.orders.index(order)]

    def table(self) -> list[list]:
        """[[order, ratio], ...] for the finding's parameters."""
        return [[n, round(r, 3)] for n, r in zip(self.orders, self.ratios)]


def truncation_ladder(taps: np.ndarray, fs: float, delay: int, spectra: list[SweepSpectrum], floor: float,
                      model=None, start: int = 2, cap: int | None = None, lowest: int = 1) -> TruncationLadder:
    """The frequency-limited truncations of the FIR ``taps`` (behind ``delay`` samples) at orders doubling from
    ``start``, validated on ``spectra`` (``tail_spectra``) against the noise ``floor`` (FS), then bisected (to
    ``LADDER_RESOLUTION``, not below ``lowest``) to the lowest order within ``target``: ``AT_FLOOR``, or
    ``TAIL_LADDER_SLACK`` times the FIR's own ratio when the FIR is above it, or times the ratio of an order whose
    double and quadruple lower it by less than ``TAIL_LADDER_SLACK`` (a plateau). Orders up to ``cap``, the model format's
    ``MAX_ORDER`` and the last Hankel singular value above ``NEGLIGIBLE_HSV`` of the first; ``model``: the model
    whose ratio is reckoned the same way (``model_ratio``)."""
    truncation = frequency_limited_truncation(taps, fs, (0.0, IDENTIFICATION_BAND[1]))
    # States of negligible Hankel singular value hold nothing, and realising them is ill-conditioned.
    hsv = truncation.hankel_singular_values
    held = int(np.count_nonzero(hsv >= NEGLIGIBLE_HSV * hsv[0]))
    top = max(1, min(held, MAX_ORDER, cap or MAX_ORDER))
    compressed = CompressedValidation(spectra, LADDER_CELL_HZ)
    cells = compressed.frequencies
    shift = np.exp(-2j * np.pi * cells * delay / fs)
    z = np.exp(2j * np.pi * cells / fs)

    def exact(response) -> float:
        return rms_from_responses(spectra, [response(s.frequencies) for s in spectra]) / floor

    fir_ratio = exact(lambda f: np.polyval(taps[::-1], np.exp(-2j * np.pi * f / fs))
                      * np.exp(-2j * np.pi * f * delay / fs))
    model_ratio = exact(model.frequency_response) if model is not None else float("nan")
    target = max(AT_FLOOR, TAIL_LADDER_SLACK * fir_ratio)
    scores: dict[int, float] = {}

    def score(n: int) -> float:
        if n not in scores:
            system, _ = truncation.realisation(n)
            scores[n] = float(compressed.rms(_response(system, z) * shift)[0]) / floor
        return scores[n]

    n = max(1, min(start, top))
    while score(n) > target and n < top:
        wider = min(2 * n, top)
        if score(n) < TAIL_LADDER_SLACK * min(score(wider), score(min(4 * n, top))):
            # Twice and four times the states buy next to nothing (a truncation's error is not monotone in its
            # order: one doubling may not pay where the next does): what is left is not for more states to take
            # (a plateau, say a slow component the truncation ranks last), and the states that pay are these.
            target = TAIL_LADDER_SLACK * score(n)
            break
        n = wider
    needed = _lowest_within(score, scores, target, lowest)
    # As well as the model: within the slack of it (a truncation of the model's own order matches it, not better).
    model_states = _lowest_within(score, scores, TAIL_LADDER_SLACK * model_ratio, 1) if model is not None else None
    orders = sorted(scores)
    ratios = [scores[k] for k in orders]
    best = orders[int(np.argmin(ratios))]
    return TruncationLadder(tuple(orders), tuple(ratios), needed, best, target, fir_ratio, model_ratio, model_states,
                            truncation)


def _lowest_within(score, scores: dict, target: float, lowest: int) -> int | None:
    """The lowest order (to ``LADDER_RESOLUTION``, not below ``lowest``) whose ``score`` is within ``target``, bisected
    down from the lowest evaluated order that is (None when none of ``scores`` is)."""
    passing = [k for k, r in scores.items() if r <= target]
    if not passing:
        return None
    high = min(passing)
    low = max([k for k in scores if k < high], default=max(lowest, 1) - 1)
    while high - low > max(1.0, LADDER_RESOLUTION * high):
        middle = (low + high) // 2
        low, high = (low, middle) if score(middle) <= target else (middle, high)
    return min(k for k, r in scores.items() if r <= target)


def _tail_shape(response: LongResponse) -> dict:
    """Where the tail starts (the direct sound TAIL_DIRECT_DB below the peak) and its level, decay and band."""
    fs, envelope, noise = response.fs, response.envelope, response.noise
    end = int(round((response.length_s - response.delay / fs) * fs))
    peak = int(np.argmax(envelope))
    after = np.flatnonzero(envelope[peak:end] < envelope[peak] * 10 ** (-TAIL_DIRECT_DB / 10))
    if end - peak < 4 or not after.size:
        return {}
    first = peak + int(after[0])
    excess = np.maximum(envelope[first:end] - noise**2, noise**2 * 1e-3)
    t_ms = 1e3 * np.arange(first, end) / fs
    slope = np.polyfit(t_ms, 10 * np.log10(excess), 1)[0] if end - first >= 4 else float("nan")
    # The band holding the central 80 % of the tail's energy, from its taps' spectrum in the identification band.
    segment = _smoothed(response.taps, fs)[first:end]
    n_fft = 1 << int(np.ceil(np.log2(max(8 * segment.size, 4096))))
    f = np.fft.rfftfreq(n_fft, 1 / fs)
    power = np.abs(np.fft.rfft(segment, n_fft)) ** 2
    inside = (f >= IDENTIFICATION_BAND[0]) & (f <= IDENTIFICATION_BAND[1])
    cumulative = np.cumsum(power[inside]) / max(np.sum(power[inside]), 1e-300)
    band = f[inside][np.searchsorted(cumulative, [0.1, 0.9])]
    return {"start_ms": 1e3 * (first + response.delay) / fs,
            "level_db": float(10 * np.log10(np.mean(excess) / envelope[peak])),
            "decay_db_per_ms": float(-slope), "band_hz": [float(band[0]), float(band[1])],
            "peak_hz": float(f[inside][np.argmax(power[inside])])}


def ladder_text(table: list, order: int, needed: int | None = None) -> str:
    """What more states would buy, from a ladder's ``table()``: the validation error at the orders above ``order``
    that at least double the last one shown, and at ``needed`` ("60 states 16.95x, 120 states 8.92x, ...")."""
    shown, last = [], 0
    for n, ratio in table:
        if n > order and (n >= 2 * last or n == needed):
            shown.append(f"{n} states {ratio:.2f}x")
            last = n if n >= 2 * last else last
    return ", ".join(shown)


def _at_delay(model: Model, total_delay: int) -> Model:
    """``model``'s core, input map and offset behind ``total_delay`` samples: what a long estimate is made behind."""
    return Model(path=model.path, fs=model.fs, A=model.A, B=model.B, C=model.C, D=model.D, delay=total_delay,
                 input_nonlinearity=model.input_nonlinearity, output_offset=model.output_offset)


def _ladder_behind(ctx: DiagnosisContext, spectra: list[SweepSpectrum], total_delay: int) -> TruncationLadder:
    """The truncation ladder of the noise recording's long estimate behind ``total_delay`` samples."""
    model = ctx.model
    taps = long_response(_at_delay(model, total_delay), ctx.noise, ctx.transient_s).taps
    return truncation_ladder(taps, ctx.fs, total_delay, spectra, ctx.comparison.noise_floor, model,
                             start=max(model.order, 2))


def _states_needed(ladder: TruncationLadder) -> tuple[float, float]:
    """Sort key: the states a ladder needs to reach its target (none reaching it last), then its best ratio."""
    needed = float("inf") if ladder.needed is None else float(ladder.needed)
    return needed, min(ladder.ratios)


@uses("long-response")
def tail_finding(ctx: DiagnosisContext):
    model = ctx.model
    cap = model.identification.get("max_order")
    if ctx.excess < EXCESS:
        return finding("reverberant-tail", False, 0.0, {"order": model.order}, "not tested: the model is at the noise floor",
                       "none")
    # A missing delay is judged beside the tail, not instead of it (a long response's onset is slow, and a capped
    # model fits it better a few samples later); any other named effect explains the error first.
    named = [f["effect"] for f in ctx.findings if f["significant"] and f["effect"] not in NO_IN_BAND_ERROR + ("delay",)]
    if named:
        return finding("reverberant-tail", False, 0.0, {"order": model.order},
                       f"not tested: {named[0]} explains the error", "none")
    response: LongResponse = ctx.value("long-response")
    fs = ctx.fs
    # The whole estimate is truncated: its taps above the band are the input roll-off's amplified noise, spread
    # over every tap, which the band's Gramian leaves out but cutting the taps short would fold into the band.
    spectra = tail_spectra(model, ctx.sweeps, ctx.comparison)
    ladder = truncation_ladder(response.taps, fs, model.delay, spectra, ctx.comparison.noise_floor, model,
                               start=max(model.order, 2))
    missing = ctx.finding("delay")
    if missing is not None and missing["significant"]:
        # A missing delay costs the truncation states of its own: the response is estimated again behind it, and
        # judged there unless that loses what the data hold before it (a measured response's slow onset: the
        # estimate behind the delay validates worse). The onset of a band-limited recording is blurred over a
        # sample (the delay's scan reads it to within one), and where the cut falls inside it decides how many
        # states the truncation spends on it: behind the delay and its two neighbours, the fewest states are kept.
        found = model.delay + int(missing["params"]["samples"])
        behind = [_ladder_behind(ctx, spectra, total) for total in (found - 1, found, found + 1) if total > model.delay]
        kept = [b for b in behind if b.fir_ratio <= TAIL_LADDER_SLACK * ladder.fir_ratio]
        if kept:
            ladder = min(kept, key=_states_needed)
    if model.delay > 0:
        # A delay the model holds may cut into a slow onset (a capped model fits it better a few samples later):
        # the response from the input on is judged instead when its estimate validates materially better.
        whole = _ladder_behind(ctx, spectra, 0)
        if TAIL_LADDER_SLACK * whole.fir_ratio < ladder.fir_ratio:
            ladder = whole
    chosen = ladder.needed if ladder.needed is not None else ladder.best
    gain = ladder.model_ratio / ladder.ratio(chosen) if ladder.ratio(chosen) > 0 else 0.0
    # The share of the error power above the floor that the states remove (as a series factor's, FACTOR_SHARE):
    # a response longer than the estimate, or an error that is no tail, leaves most of it.
    share = (1.0 - (ladder.ratio(chosen) ** 2 - 1.0) / (ladder.model_ratio ** 2 - 1.0)
             if ladder.model_ratio > 1.0 else 0.0)
    # Dense: many more states than the model's own order in the truncation's currency (a model validating as well
    # as no truncation counts at its order).
    held_states = max(model.order, ladder.model_states or 0)
    density = chosen / max(TAIL_STATES_RATIO * held_states, held_states + TAIL_MIN_EXTRA_STATES)
    at_cap = cap is not None and model.order >= cap
    if at_cap:
        # The user's cap, not the order search, set the order: the states the data need beyond it are the
        # cap's to grant, whatever currency the model's own are counted in, and the only alternative to
        # the long estimate's states is under-modelled's one more mode (2 states). The tail is named when
        # the data need more than that beyond the cap.
        density = max(density, chosen / (model.order + 3))
    significant = gain >= EXPLAINS_GAIN and share >= FACTOR_SHARE and density >= 1.0
    # Ranked by how much better the states validate; short of significance, by the condition that fails most.
    score = gain / EXPLAINS_GAIN if significant else max(0.0, min(gain / EXPLAINS_GAIN, share / FACTOR_SHARE, density))
    shape = _tail_shape(response)
    length_ms = 1e3 * response.length_s
    params = {"length_ms": length_ms, "length_complete": response.complete, "order": model.order, "max_order": cap,
              "states": chosen, "states_reach_floor": ladder.needed is not None and ladder.ratio(chosen) <= AT_FLOOR,
              "rms_over_floor": ctx.excess,
              "rms_at_states": ladder.ratio(chosen), "ladder": ladder.table(),
              "model_length_ms": 1e3 * response.model_length_s, "model_states": held_states, **shape}
    at_least = "" if response.complete else "at least "
    words = [f"the response rings for {at_least}{length_ms:.{0 if length_ms >= 10 else 1}f} ms above the noise"]
    if shape:
        words.append(f" (its tail {-shape['level_db']:.0f} dB below the peak, decaying {shape['decay_db_per_ms']:.2f} "
                     f"dB/ms, its energy mostly at {shape['band_hz'][0]:.0f}-{shape['band_hz'][1]:.0f} Hz)")
    held = f"the model holds {model.order} states" + (f" (its cap {cap})" if cap is not None and cap >= model.order else "")
    there = f"validates at {ladder.ratio(chosen):.2f}x the noise floor against the model's {ctx.excess:.2f}x"
    # The physics is named only when the tail explains the error.
    words.append(": reflections inside the shell or off the head, dense modes; " if significant else "; ")
    if params["states_reach_floor"]:
        words.append(f"{held}, the tail needs about {chosen}: the long estimate truncated there {there}")
    else:
        words.append(f"{held}; the long estimate truncated to {chosen} states {there}, and more states buy little "
                     f"(the estimate itself {ladder.fir_ratio:.2f}x)")
    words.append(f" (more states: {ladder_text(ladder.table(), model.order, chosen)})")
    explanation = "".join(words)
    if not significant:
        reason = (f"lowers the error only {gain:.2f}x" if gain < EXPLAINS_GAIN else
                  f"removes only {100 * share:.0f} % of the error power above the floor" if share < FACTOR_SHARE else
                  f"{chosen} states are not many more than the {held_states} a truncation needs to match the model "
                  f"(a few missing modes are under-modelled)")
        explanation = f"not significant: the long estimate truncated to the states the response needs {reason}; " + explanation
    remedy = f"refine --add reverberant-tail:states={chosen}" if significant else "none"
    return finding("reverberant-tail", significant, score, params, explanation, remedy,
                   {"rms_gain": gain, "error_share": share, "noise_rms": response.noise, "fir_taps": response.taps.size,
                    "fir_ratio": ladder.fir_ratio, "target_ratio": ladder.target})
