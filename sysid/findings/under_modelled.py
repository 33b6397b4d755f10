"""Too low an order: error above the noise floor that more dynamics remove (effects.md, under-modelled).

Asked last, when the model is above the noise floor and no named effect explains
it: one more mode (2 states), started at the third-octave band worst against the
noise floor (``sysid.validation.compare.worst_bands``), is fitted together with the model's
own poles by a quick output-error refit (``sysid.findings.delay.refit_rms``). If that lowers the validation rms by
``GAIN`` the model is under-modelled: a nominal-order fit of a path with an extra
resonance or filter takes it in and gives up a weaker mode, and the error is then
spread over a band rather than shaped like any one factor.
"""

from __future__ import annotations

from ..core.structures import mode_block, with_states
from ..core.thresholds import EXCESS, EXPLAINS_GAIN, UNDER_MODELLED_EXCESS
from ..validation.compare import START_Q, worst_bands
from . import DiagnosisContext, finding, uses
from .delay import refit_rms

__all__ = ["under_modelled_finding"]

GAIN = EXPLAINS_GAIN
NO_IN_BAND_ERROR = ("dc-offset", "time-variation")


@uses("delay-scan-data", "delay-sweep-spectra")
def under_modelled_finding(ctx: DiagnosisContext) -> dict:
    model = ctx.model
    # An offset (at DC) or a change between recordings explains no in-band error of the model.
    explained = any(f["significant"] and f["effect"] not in NO_IN_BAND_ERROR for f in ctx.findings)
    if ctx.excess < EXCESS or explained:
        reason = "the model is at the noise floor" if ctx.excess < EXCESS else "a named effect explains the error"
        return finding("under-modelled", False, 0.0, {"order": model.order}, f"not tested: {reason}", "none")
    band = worst_bands(ctx.comparison)[0]
    A, B, C = with_states(model.A, model.B, model.C, mode_block(band["center_hz"], START_Q, model.fs))
    reference = refit_rms(ctx, model.A, model.B, model.C, model.D, model.delay)
    larger = refit_rms(ctx, A, B, C, model.D, model.delay, max_iterations=30)
    gain = ctx.comparison.rms / larger if larger > 0 else 0.0
    # The refit of the model as it is shows how much is mere parameter drift, not order.
    order_gain = reference / larger if larger > 0 else 0.0
    significant = gain >= GAIN and order_gain >= GAIN
    # Far above the floor with nothing named, "nothing significant" is no answer: the model lacks
    # something the named detectors do not know, and more order is the first thing to try.
    fallback = not significant and ctx.excess >= UNDER_MODELLED_EXCESS
    above = [r for r in ctx.comparison.bands if r["ratio"] > UNDER_MODELLED_EXCESS]
    span = f"{above[0]['low_hz']:.0f}-{above[-1]['high_hz']:.0f} Hz" if above else f"the {band['center_hz']:.0f} Hz band"
    explanation = (f"the error is {ctx.excess:.1f}x the noise floor over {span} (worst {band['ratio']:.1f}x at "
                   f"{band['center_hz']:.0f} Hz) and no single delay, factor or disturbance explains it; one more "
                   f"mode lowers it {gain:.2f}x: order {model.order} is too low for the dynamics in band")
    if fallback:
        explanation = (f"the error is {ctx.excess:.1f}x the noise floor over {span} (worst {band['ratio']:.1f}x at "
                       f"{band['center_hz']:.0f} Hz) and no named effect explains it; one more mode alone lowers it "
                       f"{gain:.2f}x: try order {model.order + 2} or more, or look for an effect not in the registry")
    elif not significant:
        # Then order is not what is missing: say so rather than call the order too low.
        explanation = (f"not significant: the error is {ctx.excess:.1f}x the noise floor over {span}, but with one "
                       f"more mode it is {1 / max(gain, 1e-12):.2f} times what it is now, so order {model.order} is "
                       f"not what the model lacks")
    score = min(gain, order_gain) / GAIN
    return finding("under-modelled", significant or fallback, max(score, 1.0) if fallback else score,
                   {"order": model.order, "suggested_order": model.order + 2, "worst_band_hz": band["center_hz"],
                    "worst_band_ratio": band["ratio"],
                    "bands_hz": [[round(r["low_hz"], 1), round(r["high_hz"], 1)] for r in above]},
                   explanation, "refine --add under-modelled" if significant or fallback else "none",
                   {"rms_over_floor": ctx.excess, "rms_gain": gain, "gain_over_refit": order_gain})
