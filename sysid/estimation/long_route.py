"""The long route: models of any length the data hold, from a least-squares FIR, without iterating.

Real acoustic paths ring for tens of milliseconds and need tens to hundreds of states
(design.md, identification step 7). The order search of ``sysid.estimation.order_search``
reaches them only slowly and stops at its cap; this route reaches them in seconds:

1. ``long_estimate``: the least-squares FIR of the noise recording from lag 0
   (``long_response.fir_estimate``), of ``FIR_FIRST_TAPS`` taps, doubled up to ``FIR_MAX_TAPS``
   while the response needs more than ``FIR_HOLDS`` of them. The taps the response needs are
   decided on the sweeps: the nested least-squares FIR of every length (one Cholesky factor
   gives them all) validated on the sweeps' spectra, the fewest taps within ``FIR_TAIL_SHARE``
   of the noise floor's power of the best length's. On the sweeps, not on the noise recording:
   an exponential sweep weighs the bass, where a headphone's late taps lie, twenty times more
   than low-passed white noise does (the HD 600's last 110 of 2048 taps move the noise
   recording's residual by 1 % and the sweeps' validation rms from 1.07 to 1.24 times the floor).
   More taps than that add only the estimate's noise (4096 taps of the HD 600: 1.12x).
2. The delay, decided once before any order (``sysid.estimation.delay.fir``): the leading taps
   the data cannot tell from zero. The core's FIR is then estimated behind it (a fresh fit:
   the long estimate's taps cut at the delay would leak their large error above the input's
   band into it).
3. Its frequency-limited balanced truncation (``long_response.frequency_limited_truncation``) to
   every order, validated on the sweeps: the order/error curve (``order_curve.ladder``) and the
   lowest order at the floor.
4. ``refine_long``: at the order chosen, output error on the raw DFT of the noise recording
   where affordable (``LONG_OE_ORDER``: it lowers the order at which the floor is reached), else the
   numerator with the poles held (one linear least-squares step on the raw data); each kept
   only when it validates better on the sweeps.

Whether a session takes this route or the order search is ``sysid.identify``'s decision: an
FIR that does not hold the response (a lightly damped low mode rings for seconds: Q 50 at
35 Hz for 0.45 s per neper) leaves the rational plant to the order search.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.stats

from ..core import lti
from ..core.thresholds import (FIR_FIRST_TAPS, FIR_HOLDS, FIR_LENGTHS, FIR_MAX_TAPS, FIR_SECONDS, FIR_TAIL_SHARE,
                               LONG_OE_ITERATIONS,
                               LONG_OE_ORDER, MIN_GAIN, ORDER_AT_FLOOR)
from ..io.recordings import Recording, RecordingFile
from ..validation.sweeps import SweepSpectrum, rms_from_responses, sweep_spectrum
from .delay.fir import FirDelay, fir_delay
from .delay.onset import compensate_delay
from .long_response import (FirEstimate, FrequencyLimitedTruncation, fir_estimate, frequency_limited_truncation,
                            system_response)
from .output_error import BlockData, at_radius_bound, refine_output_error
from .order_curve import OrderCurve, ladder

__all__ = ["LongEstimate", "long_estimate", "fir_rms", "fir_length", "core_rms", "LongModel", "refine_long", "fir_band"]


@dataclass
class LongEstimate:
    """What the long route found before any order was chosen (module docstring, steps 1-3).

    ``fir``: the longest estimate, from lag 0; ``length``: the taps the response needs, from lag 0 (``held``: the
    estimate is longer than that by a margin); ``lengths``: the nested fits' validation rms (FS) by length;
    ``delay``: the leading taps the data cannot tell from zero; ``line`` the model's delay line (samples) and
    ``feedthrough`` whether its core has a direct term; ``core_taps`` the core's FIR behind the line (taps[0] its
    direct term), from the estimate ``core_fir``, and ``core_sweeps`` the sweeps' spectra behind the line;
    ``truncation`` and ``curve`` its truncation ladder and order/error curve. From ``delay`` on, None (or empty)
    where the estimate does not hold the response. ``seconds``: what each step took.
    """

    fir: FirEstimate
    length: int
    held: bool
    lengths: dict[int, float]
    delay: FirDelay | None = None
    line: int = 0
    feedthrough: bool = False
    core_taps: np.ndarray | None = None
    core_sweeps: list[SweepSpectrum] = field(default_factory=list)
    core_fir: FirEstimate | None = None
    truncation: FrequencyLimitedTruncation | None = None
    curve: OrderCurve | None = None
    seconds: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"fir_taps": self.fir.length, "response_taps": self.length, "held": self.held,
                "response_ms": round(1000.0 * self.length / self.fir.fs, 2),
                "delay_taps": None if self.delay is None else self.delay.taps}


def _bins(spectrum: SweepSpectrum) -> np.ndarray:
    return np.rint(spectrum.frequencies * spectrum.length / spectrum.fs).astype(int)


def fir_rms(taps: np.ndarray, sweeps: list[SweepSpectrum]) -> float:
    """Validation rms (FS) of the FIR ``taps`` on the sweeps' spectra: its response at their bins exactly, by a DFT
    of each sweep's length (one for sweeps of one length)."""
    responses = []
    for s in sweeps:
        if responses and s.length == sweeps[0].length and np.array_equal(s.frequencies, sweeps[0].frequencies):
            responses.append(responses[0])
        elif s.length >= taps.size:
            responses.append(np.fft.rfft(taps, s.length)[_bins(s)])
        else:
            responses.append(np.polynomial.polynomial.polyval(np.exp(-2j * np.pi * s.frequencies / s.fs), taps))
    return rms_from_responses(sweeps, responses)


def fir_length(estimate: FirEstimate, sweeps: list[SweepSpectrum], floor: float, share: float = FIR_TAIL_SHARE,
               holds: float = 1.0) -> tuple[int, dict[int, float]]:
    """The taps the response needs (module docstring, step 1), and the validation rms (FS) of the nested fits
    tried, by length. When even ``holds`` of the estimate's taps are too few, the answer is the estimate's length
    (found from two fits: the longest is at most the best's rms)."""
    tried: dict[int, float] = {}

    def rms(length: int) -> float:
        if length not in tried:
            tried[length] = fir_rms(estimate.nested(length), sweeps)
        return tried[length]

    longest = estimate.length
    if holds < 1.0 and rms(int(holds * longest)) ** 2 > rms(longest) ** 2 + share * floor**2:
        return longest, dict(sorted(tried.items()))
    grid = sorted({int(round(x)) for x in np.geomspace(8, longest, FIR_LENGTHS)} | {longest} | set(tried))
    best = min(rms(n) for n in grid)
    limit = np.sqrt(best**2 + share * floor**2)
    first = next(n for n in grid if rms(n) <= limit)
    below = max((n for n in grid if n < first), default=0)
    while first - below > 1:
        middle = (first + below) // 2
        if rms(middle) <= limit:
            first = middle
        else:
            below = middle
    return first, dict(sorted(tried.items()))


def _arrays(noise: Recording | RecordingFile, transient_s: float) -> tuple[np.ndarray, np.ndarray, int]:
    """(u, y, start): the noise recording's first seconds in memory, the transient kept as the input's history."""
    head = noise.head(transient_s + FIR_SECONDS)
    return head.u, head.y, int(round(transient_s * noise.fs))


def long_estimate(noise: Recording | RecordingFile, sweeps: list[Recording], floor: float, band: tuple[float, float],
                  validation_band: tuple[float, float], transient_s: float, max_delay: int | None = None,
                  feedthrough: bool = False, at_floor: float = ORDER_AT_FLOOR, min_gain: float = MIN_GAIN,
                  ladder_max: int | None = None, force: bool = False) -> LongEstimate:
    """The long route's estimate of one session (module docstring, steps 1-3); the truncation ladder only where the
    FIR holds the response, or when ``force``d.

    ``noise``: the whole noise recording (its first ``transient_s`` serve as the input's history); ``sweeps``: the
    two sweeps (their lines taken out); ``floor``: their noise floor (FS); ``band``: the identification band (Hz),
    whose top bounds the truncation's band.
    """
    seconds = {}
    t0 = time.perf_counter()
    u, y, start = _arrays(noise, transient_s)
    raw_sweeps = [sweep_spectrum(s, validation_band) for s in sweeps]
    taps = min(FIR_FIRST_TAPS, FIR_MAX_TAPS)
    while True:
        taps = min(taps, (y.size - start) // 4, (start + 1) // 2)
        estimate = fir_estimate(u, y, noise.fs, taps, start)
        length, lengths = fir_length(estimate, raw_sweeps, floor, holds=FIR_HOLDS)
        held = length <= FIR_HOLDS * taps
        if held or taps >= FIR_MAX_TAPS or 2 * taps > min((y.size - start) // 4, (start + 1) // 2):
            break
        taps *= 2
    seconds["long FIR"] = time.perf_counter() - t0
    result = LongEstimate(estimate, length, held, lengths, seconds=seconds)
    if not (held or force):
        return result
    t0 = time.perf_counter()
    # The delay, then the core behind the delay line: taps from the delay's on, refitted (module docstring, step 2).
    result.delay = fir_delay(estimate, max_delay)
    d = result.delay.taps
    result.feedthrough = feedthrough or d == 0
    result.line = d if result.feedthrough else d - 1
    result.core_fir = fir_estimate(u[: u.size - d], y[d:], noise.fs, max(length - d, 2), start)
    taps_behind = result.core_fir.taps
    result.core_taps = taps_behind if result.feedthrough else np.concatenate(([0.0], taps_behind))
    result.core_sweeps = [sweep_spectrum(compensate_delay(s, result.line), validation_band) for s in sweeps]
    result.truncation = frequency_limited_truncation(result.core_taps, noise.fs, (0.0, band[1]))
    result.curve = ladder(result.truncation, result.core_sweeps, floor, at_floor, min_gain, max_order=ladder_max)
    seconds["truncation ladder"] = time.perf_counter() - t0
    return result


def core_rms(system, sweeps: list[SweepSpectrum]) -> float:
    """Validation rms (FS) of the core ``system`` (A, B, C, D) on the sweeps' spectra behind its delay line, exactly
    at their bins (``long_response.system_response``: hundreds of states without dense solves per bin)."""
    responses = []
    for s in sweeps:
        if responses and np.array_equal(s.frequencies, sweeps[0].frequencies):
            responses.append(responses[0])
        else:
            responses.append(system_response(*system, np.exp(2j * np.pi * s.frequencies / s.fs)))
    return rms_from_responses(sweeps, responses)


@dataclass
class LongModel:
    """A core of the long route (A, B, C, D) behind the estimate's delay line, its validation rms on the sweeps'
    spectra (FS), and how it was obtained (``refinement``: "truncation", "output error" or "numerator")."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    rms: float
    order: int
    refinement: str
    reflected: int = 0
    tried: dict[int, float] = field(default_factory=dict)


def _truncated(estimate: LongEstimate, order: int) -> LongModel:
    system, reflected = estimate.truncation.system(order)
    system = lti.balanced_realisation(*system)
    return LongModel(*system, core_rms(system, estimate.core_sweeps), order, "truncation", reflected)


def _output_error(estimate: LongEstimate, start: LongModel, block: BlockData, iterations: int) -> LongModel:
    fit = refine_output_error(start.A, start.B, start.C, start.D, block, feedthrough=estimate.feedthrough,
                              max_iterations=iterations, noise_tolerance=True)
    system = (fit.A, fit.B, fit.C, fit.D)
    if at_radius_bound(np.linalg.eigvals(fit.A), block):
        return LongModel(*system, np.inf, start.order, "output error", start.reflected)
    kind = "output error" if iterations > 1 else "numerator"
    return LongModel(*system, core_rms(system, estimate.core_sweeps), start.order, kind, start.reflected)


def refine_long(estimate: LongEstimate, order: int, block: BlockData, floor: float, lower: bool = True,
                at_floor: float = ORDER_AT_FLOOR, min_gain: float = MIN_GAIN, polish: bool = True) -> LongModel:
    """The core of ``order`` states (module docstring, step 4), or one of fewer states at the floor.

    Up to ``LONG_OE_ORDER`` states, output error from the truncation (``LONG_OE_ITERATIONS`` evaluations of
    ``block``) where it validates better; and with ``lower``, the orders below on the ladder tried the same way, from
    the highest down, while one reaches the floor (within ``at_floor`` times it, or within ``min_gain`` of the best
    model's rms): output error reaches at fewer states what the truncation reaches (the FABIAN HRIR: truncated
    to 20 states 1.46x, refined 1.20x). Above it, the numerator with the truncation's poles held (one
    linear least-squares step on the block), kept where it validates better, when the truncation is above what the
    data allow (the FIR's own validation rms, ``route.enough``: at hundreds of states output error and the
    numerator's refit cost seconds and gain nothing there; the HD 600 at 333 states: 1.09x truncated, 1.25x refined).
    Not with ``polish`` false: the caller has a model of fewer states at the floor to fall back on.
    """
    best = _truncated(estimate, order)
    tried = {order: best.rms}
    if order <= LONG_OE_ORDER:
        refined = _output_error(estimate, best, block, LONG_OE_ITERATIONS)
        tried[order] = min(tried[order], refined.rms)
        best = refined if refined.rms < best.rms else best
        if lower:
            limit = max(at_floor * floor, best.rms * (1 + min_gain))
            for n in sorted((n for n in estimate.curve.orders if n < order), reverse=True):
                start = _truncated(estimate, n)
                candidate = _output_error(estimate, start, block, LONG_OE_ITERATIONS)
                candidate = candidate if candidate.rms < start.rms else start
                tried[n] = candidate.rms
                if candidate.rms > limit:
                    break
                best = candidate
    elif polish and best.rms > max(at_floor * floor, min(estimate.lengths.values()) * (1 + min_gain)):
        # Above what the data allow (a cap below the floor's order): the numerator refitted on the raw data.
        polished = _output_error(estimate, best, block, 1)
        tried[order] = min(tried[order], polished.rms)
        best = polished if polished.rms < best.rms else best
    best.tried = dict(sorted(tried.items()))
    return best


def fir_band(estimate: LongEstimate, system, frequencies_hz: np.ndarray) -> dict:
    """The 95 % band of a long-route core (``sysid.core.model``'s ``uncertainty``: a bound on
    |H_model - H_true| / |H_model| per frequency) from the FIR it was reduced from, for models of more states
    than the output-error covariance of ``sysid.estimation.uncertainty`` affords.

    |H_model - H_true| <= |H_model - H_FIR| + |H_FIR - H_true|: the model's departure from the least-squares
    FIR, and the FIR's own error, whose variance at a frequency where the input's spectrum Phi_u is smooth is
    sigma^2 L / (N Phi_u) (L taps, N samples, sigma^2 the residual variance; Ljung, "System Identification",
    2nd ed., eq. 9.62 with the FIR's covariance sigma^2 R^-1); a circular error of variance V lies within
    sqrt(chi2_2(0.95) V / 2) with probability 0.95.
    """
    fir = estimate.core_fir
    f = np.asarray(frequencies_hz, dtype=float)
    z = np.exp(2j * np.pi * f / fir.fs)
    model = system_response(*system, z)
    data = np.polynomial.polynomial.polyval(1.0 / z, estimate.core_taps)
    grid = np.linspace(0.0, fir.fs / 2.0, fir.input_psd.size)
    psd = np.interp(f, grid, fir.input_psd)
    variance = fir.residual_variance * fir.length / (fir.samples * psd)
    bound = np.sqrt(scipy.stats.chi2.ppf(0.95, 2) * variance / 2.0) + np.abs(model - data)
    magnitude = np.maximum(np.abs(model), np.finfo(float).tiny)
    return {"frequencies_hz": [float(x) for x in f], "relative_95": [float(x) for x in bound / magnitude],
            "method": f"the least-squares FIR's 95 % error ({fir.length} taps, {fir.samples} samples) and the model's "
                      "departure from it", "block_seconds": float(fir.samples / fir.fs)}
