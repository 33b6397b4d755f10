"""Missing pure delay: a scan of the delay with the model's poles held fixed (effects.md, delay).

For each candidate delay d the model's zeros, gain and block transient are re-fitted
by linear least squares on the raw DFT of the noise recording (the linear step of
``sysid.estimation.output_error``), poles fixed. A delay the model lacks shows as a clear
minimum of that cost at d > current delay; 1 sample is 22.7 us or 0.78 cm of sound
path at 44.1 kHz. A short delay moves that cost little; when the scan is not
decisive, quick output-error refits with and without the delay are compared on
the sweeps; when the model's poles are bent to mimic the delay (the scan is flat),
a scan with a generic pole set proposes the delay to try. Both scans are the delay's
rules (``sysid.estimation.delay.fixed_pole_scan``, ``generic_pole_scan``); the coarse
scan at the model's poles is the shared value ``delay-scan``, which the report draws.
"""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from ..core import lti
from ..core.thresholds import (EXCESS, EXPLAINS_GAIN, FACTOR_EXPLAINS, IDENTIFICATION_BAND, LEADING_PHASE_DEG,
                               MAX_EXTRA_DELAY, TAIL_LADDER_SLACK)
from ..estimation.delay import delay_centimetres, fixed_pole_scan, generic_pole_scan, generic_start
from ..estimation.output_error import BlockData, block_data, refine_output_error
from ..io.recordings import Recording
from ..validation.sweeps import VALIDATION_BAND, rms_from_responses, sweep_spectrum
from . import DiagnosisContext, finding, provider, uses
from .dynamics import arbitrate, series_factor_finding
from .tail import estimate_ratio

__all__ = ["delay_finding", "scan_delay", "generic_scan", "refit_rms"]

# The best delay must lower the fixed-pole cost by this factor, and the model must be
# this far above the noise floor, before a delay is called missing.
COST_RATIO = 1.05
CLEAR_RATIO = 1.5
REFIT_GAIN = EXPLAINS_GAIN


@provider("delay-scan-data")
def _scan_data(ctx: DiagnosisContext) -> BlockData:
    """The shared value ``delay-scan-data``: the noise recording's 1 s block data for the delay scan."""
    body = ctx.body
    v = ctx.model.apply_input_nonlinearity(body.u)
    full = block_data(Recording(v, body.y, body.fs, body.path), IDENTIFICATION_BAND, 1.0)
    # Every 4th bin of a 1 s block: the cost's shape in d is kept, the solve is 4x cheaper.
    return BlockData(full.z[::4], full.U[::4], full.Y[::4], full.length, full.fs)


@provider("delay-sweep-spectra")
def _sweep_spectra(ctx: DiagnosisContext) -> list:
    """The shared value ``delay-sweep-spectra``: the sweeps' DFT bins, input through the model's polynomial."""
    model = ctx.model
    return [sweep_spectrum(Recording(model.apply_input_nonlinearity(s.u), s.y, s.fs, s.path)) for s in ctx.sweeps]


def refit_rms(ctx: DiagnosisContext, A, B, C, D, delay: int, max_iterations: int = 20) -> float:
    """Validation rms of a quick output-error refit from (A, B, C, D) with the given total delay.

    The refit runs a few iterations on the scan data (every 4th bin of 1 s of the
    noise recording); the rms is evaluated on the sweeps' DFT bins
    (``sysid.validation.rms_from_responses``).
    """
    spectra = ctx.value("delay-sweep-spectra")
    with threadpool_limits(limits=1, user_api="blas"):
        fit = refine_output_error(A, B, C, D, ctx.value("delay-scan-data"), delay=delay, max_iterations=max_iterations,
                                  feedthrough=bool(D[0, 0]))
    responses = []
    for k, s in enumerate(spectra):
        same = next((r for p, r in zip(spectra[:k], responses) if np.array_equal(p.frequencies, s.frequencies)), None)
        if same is not None:
            # Repeated sweeps of one length share their bins: one response (a model whose modal form is
            # unreliable is evaluated by a solve per bin, 0.1 s for 20 000 bins).
            responses.append(same)
            continue
        z = np.exp(2j * np.pi * s.frequencies / s.fs)
        responses.append(lti.frequency_response(fit.A, fit.B, fit.C, fit.D, z) * z ** (-delay))
    return rms_from_responses(spectra, responses)


def confirm_delay(ctx: DiagnosisContext, totals) -> dict[int, float]:
    """Validation-rms gain of quick refits (``refit_rms``) with each total delay over the best refit with the
    model's: each from the model and from a fresh start behind its delay (``generic_start``, the model's order).

    A model fitted without the delay bends its poles to mimic it, and refitted from there it stays near
    itself, with or without the delay (random FB helmet 31 behind 31 samples, 6 states at 633x the floor:
    519x from the model at its delay, 458x at 31; from the fresh starts 26x and 1.8x). A fresh start's local
    minimum is no reference (clean random FB helmet 531, 16 states at 1.42x: fresh 4.4x worse at its delay than
    a sample later), so each delay is judged against the better of the two refits at the model's delay."""
    m = ctx.model
    data, feedthrough = ctx.value("delay-scan-data"), bool(m.D[0, 0])
    starts = [lambda d: (m.A, m.B, m.C, m.D), lambda d: generic_start(data, ctx.fs, d, m.order, feedthrough)]

    def refit(start, d: int) -> float:
        system = start(d)
        return float("inf") if system is None else refit_rms(ctx, *system, d)

    reference = min(refit(start, m.delay) for start in starts)
    return {int(d): (reference / rms if rms > 0 else 0.0) for d in totals
            for rms in [min(refit(start, int(d)) for start in starts)]}


def generic_scan(ctx: DiagnosisContext, max_extra: int = MAX_EXTRA_DELAY) -> int:
    """Best total delay with a fixed generic pole set instead of the model's poles
    (``sysid.estimation.delay.generic_pole_scan`` on the scan data)."""
    return generic_pole_scan(ctx.value("delay-scan-data"), ctx.fs, ctx.model.delay, max_extra)


def scan_delay(ctx: DiagnosisContext, max_extra: int = MAX_EXTRA_DELAY, coarse: bool = False) -> tuple[int, np.ndarray]:
    """(best total delay, cost per total delay 0..current+max_extra) at the model's poles on the scan data
    (``sysid.estimation.delay.fixed_pole_scan``; ``coarse``: every second delay and the neighbours of the best,
    NaN where not evaluated)."""
    return fixed_pole_scan(ctx.model.A, ctx.value("delay-scan-data"), ctx.model.delay, max_extra, coarse)


@provider("delay-scan")
def _coarse_scan(ctx: DiagnosisContext) -> tuple[int, np.ndarray]:
    """The shared value ``delay-scan``: (best total delay, fixed-pole cost per total delay 0..model.delay +
    ``MAX_EXTRA_DELAY``, NaN where the coarse scan did not evaluate), ``scan_delay(ctx, coarse=True)``: what the
    finding decides from and the report draws."""
    return scan_delay(ctx, coarse=True)


@uses("delay-scan", "delay-scan-data", "delay-sweep-spectra", "sweep-bins", "long-response")
def delay_finding(ctx: DiagnosisContext) -> dict:
    model = ctx.model
    best, costs = ctx.value("delay-scan")
    extra = best - model.delay
    ratio = float(costs[model.delay] / costs[best])
    # A model at the noise floor needs no delay, unless the scan is unambiguous (the floor
    # itself may be inflated, e.g. by hum that differs between the repeats). A short delay
    # moves the fixed-pole cost little; a quick refit with and without it decides.
    significant = extra >= 1 and ratio >= COST_RATIO and (ctx.excess >= EXCESS or ratio >= CLEAR_RATIO)
    refit_gain = None
    # The slower checks below are for an error nothing else explains; a series factor that
    # brings the sweeps near the noise floor does.
    factor = series_factor_finding(ctx)
    explained = factor is not None and factor["evidence"]["rms_with_factor"] <= FACTOR_EXPLAINS * ctx.comparison.noise_floor
    if not significant and ctx.excess >= EXCESS and not explained:
        if extra < 1 or ratio < COST_RATIO:
            # The model's poles may be bent to mimic the delay: scan with generic poles.
            generic = generic_scan(ctx)
            if generic - model.delay >= 2:
                best = generic
        if best - model.delay >= 1:
            # The onset is blurred by a sample or two: the quick refits pick among the neighbours.
            gains = confirm_delay(ctx, range(max(best - 2, model.delay + 1), best + 1))
            best = max(gains, key=gains.get)
            extra, refit_gain = best - model.delay, gains[best]
            significant = refit_gain >= REFIT_GAIN
            ratio = max(ratio, COST_RATIO * refit_gain / REFIT_GAIN)
    onset = None
    if significant and extra >= 1 and ctx.excess >= EXCESS:
        # A pure delay is a stretch in which nothing arrives: the long least-squares FIR (free to hold any onset,
        # any detail) then validates as well behind it as from the model's delay. When it validates worse, the data
        # hold response there (a slow onset), and the scan's minimum only moves the error of a model too short for
        # the response (a capped one) to where it costs less: no delay.
        onset = (estimate_ratio(ctx, model.delay), estimate_ratio(ctx, best))
        if onset[1] > TAIL_LADDER_SLACK * onset[0]:
            significant = False
    microseconds = 1e6 * extra / model.fs
    # Excess phase of the missing delay at the top of the validation band (effects.md: linear in f).
    excess_phase = 360.0 * VALIDATION_BAND[1] * max(extra, 0) / model.fs
    centimetres = delay_centimetres(extra, model.fs)
    if extra >= 1:
        explanation = (f"the model fits best with {extra} more sample(s) of delay ({microseconds:.0f} us): about "
                       f"{centimetres:.1f} cm of sound path or converter latency; without it the fit needs spurious "
                       f"non-minimum-phase zeros (fixed-pole cost falls {ratio:.2f}x at delay {best})")
    else:
        explanation = "no delay beyond the model's own lowers the fit cost"
    if onset is not None and not significant:
        explanation = (f"not significant: the response starts before it (the long least-squares estimate behind "
                       f"{extra} more sample(s) validates at {onset[1]:.2f}x the noise floor against {onset[0]:.2f}x "
                       f"from the model's delay): the fixed-pole cost falls {ratio:.2f}x at delay {best} only because "
                       f"the model is too short for the response")
    score = ratio / COST_RATIO if extra >= 1 else 0.0
    if onset is not None and not significant:
        # Ranked by the condition that fails: how much worse the estimate validates behind the delay.
        score = min(score, TAIL_LADDER_SLACK * onset[0] / onset[1])
    found = finding("delay", significant, score,
                   {"samples": extra, "total_samples": best, "microseconds": microseconds, "sound_path_cm": centimetres},
                   explanation, f"refine --add delay:{extra}" if extra >= 1 else "none",
                   {"cost_ratio": ratio, "rms_over_floor": ctx.excess, "refit_gain": refit_gain,
                    "excess_phase_deg": excess_phase,
                    "estimate_ratios": list(onset) if onset is not None else None, "leads": bool(significant and excess_phase >= LEADING_PHASE_DEG)})
    arbitrate(found, ctx)
    return found
