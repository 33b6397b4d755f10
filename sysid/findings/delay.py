"""Missing pure delay: a scan of the delay with the model's poles held fixed (effects.md, delay).

For each candidate delay d the model's zeros, gain and block transient are re-fitted
by linear least squares on the raw DFT of the noise recording (the linear step of
``sysid.estimation.output_error``), poles fixed. A delay the model lacks shows as a clear
minimum of that cost at d > current delay; 1 sample is 22.7 us or 0.78 cm of sound
path at 44.1 kHz. A short delay moves that cost little; when the scan is not
decisive, quick output-error refits with and without the delay are compared on
the sweeps; when the model's poles are bent to mimic the delay (the scan is flat),
a scan with a generic pole set proposes the delay to try.
"""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from ..core import lti
from ..core.thresholds import EXCESS, EXPLAINS_GAIN, FACTOR_EXPLAINS, IDENTIFICATION_BAND, LEADING_PHASE_DEG
from ..estimation.output_error import BlockData, block_data, linear_cost, refine_output_error
from ..io.recordings import Recording
from ..validation.sweeps import VALIDATION_BAND, rms_from_responses, sweep_spectrum
from . import SPEED_OF_SOUND, DiagnosisContext, finding, provider, uses
from .dynamics import arbitrate, series_factor_finding

__all__ = ["delay_finding", "scan_delay", "refit_rms", "MAX_EXTRA_DELAY"]

MAX_EXTRA_DELAY = 120
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
    model = ctx.model
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
    """Validation-rms gain of quick refits (``refit_rms``) with each total delay over one with the model's."""
    m = ctx.model
    reference = refit_rms(ctx, m.A, m.B, m.C, m.D, m.delay)
    return {int(d): (reference / rms if rms > 0 else 0.0) for d in totals
            for rms in [refit_rms(ctx, m.A, m.B, m.C, m.D, int(d))]}


def generic_scan(ctx: DiagnosisContext, max_extra: int = MAX_EXTRA_DELAY) -> int:
    """Best total delay with a fixed generic pole set instead of the model's poles.

    Second-order modes with Q = 2 at 12 log-spaced frequencies from 30 Hz to 4.5 kHz
    (and two slow real poles) describe any smooth path response but no delay, so the
    cost's minimum over d marks the delay even when the model's own poles, bent to
    mimic the delay, make the fixed-pole scan flat. Coarse steps of 2, then +-1.
    """
    model = ctx.model
    f0 = np.geomspace(30.0, 4500.0, 12)
    upper = np.exp(-np.pi * f0 / (2.0 * ctx.fs)) * np.exp(2j * np.pi * f0 / ctx.fs)
    A = lti.real_block_diagonal(np.concatenate([upper, np.conj(upper), [0.9, 0.99]]))
    data = ctx.value("delay-scan-data")
    with threadpool_limits(limits=1, user_api="blas"):
        coarse = {d: linear_cost(A, data, d) for d in range(model.delay, model.delay + max_extra + 1, 2)}
        centre = min(coarse, key=coarse.get)
        fine = {d: coarse.get(d) or linear_cost(A, data, d) for d in range(max(centre - 1, model.delay), centre + 2)}
    return min(fine, key=fine.get)


def scan_delay(ctx: DiagnosisContext, max_extra: int = MAX_EXTRA_DELAY, coarse: bool = False) -> tuple[int, np.ndarray]:
    """(best total delay, cost per total delay 0..current+max_extra).

    ``coarse``: every second delay (and the model's own), then the neighbours of the best
    (as ``generic_scan``); the delays not evaluated hold NaN. The cost falls over a few
    samples towards a missing delay, so the step of 2 still lands next to its minimum.
    """
    model = ctx.model
    data = ctx.value("delay-scan-data")
    delays = np.arange(0, model.delay + max_extra + 1)
    costs = np.full(delays.size, np.nan)
    with threadpool_limits(limits=1, user_api="blas"):
        first = sorted(set(range(0, delays.size, 2)) | {model.delay}) if coarse else range(delays.size)
        for d in first:
            costs[d] = linear_cost(model.A, data, int(d))
        if coarse:
            centre = int(np.nanargmin(costs))
            for d in range(max(centre - 1, 0), min(centre + 2, delays.size)):
                if np.isnan(costs[d]):
                    costs[d] = linear_cost(model.A, data, int(d))
    return int(delays[np.nanargmin(costs)]), costs


@uses("delay-scan-data", "delay-sweep-spectra", "sweep-bins")
def delay_finding(ctx: DiagnosisContext) -> dict:
    model = ctx.model
    best, costs = scan_delay(ctx, coarse=True)
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
    microseconds = 1e6 * extra / model.fs
    # Excess phase of the missing delay at the top of the validation band (effects.md: linear in f).
    excess_phase = 360.0 * VALIDATION_BAND[1] * max(extra, 0) / model.fs
    centimetres = 100.0 * SPEED_OF_SOUND * extra / model.fs
    if extra >= 1:
        explanation = (f"the model fits best with {extra} more sample(s) of delay ({microseconds:.0f} us): about "
                       f"{centimetres:.1f} cm of sound path or converter latency; without it the fit needs spurious "
                       f"non-minimum-phase zeros (fixed-pole cost falls {ratio:.2f}x at delay {best})")
    else:
        explanation = "no delay beyond the model's own lowers the fit cost"
    found = finding("delay", significant, ratio / COST_RATIO if extra >= 1 else 0.0,
                   {"samples": extra, "total_samples": best, "microseconds": microseconds, "sound_path_cm": centimetres},
                   explanation, f"refine --add delay:{extra}" if extra >= 1 else "none",
                   {"cost_ratio": ratio, "rms_over_floor": ctx.excess, "refit_gain": refit_gain,
                    "excess_phase_deg": excess_phase, "leads": bool(significant and excess_phase >= LEADING_PHASE_DEG)})
    arbitrate(found, ctx)
    return found
