"""clock-drift: separate input and ear sample clocks, +-100 ppm (effects.md).

Simulated as an ear channel sampled ppm fast (positive) or slow; detected as a delay
that grows along the noise recording (``sysid.findings.variation.clock_drift_finding``);
corrected by resampling the ear channel by the estimated ratio, which the model keeps
as ``clock_ratio`` (``sysid.refits.add_clock_drift``).
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from ..core.errors import IdentificationError
from .registry import Effect, register

__all__ = ["CLOCK_DRIFT"]


def _complete(params, ctx, before):
    if params["ppm"] is None:
        from ..findings.variation import clock_drift_finding  # the detectors load when first asked
        found = clock_drift_finding(ctx)
        if not found["significant"]:
            raise IdentificationError("--add clock-drift: the noise recording shows no clock drift; give clock-drift:PPM")
        params["ppm"] = found["params"]["ppm"]
    return params


def _random(rng):
    ppm = float(rng.uniform(20, 100) * rng.choice([-1, 1]))
    return f"clock-drift:{ppm:.1f}", "ppm", ppm


CLOCK_DRIFT = register(Effect(
    name="clock-drift", summary="ear clock against input clock, parts per million (positive: ear fast)",
    simulate_params=(ParameterSpec("ppm", 50.0, -2000.0, 2000.0),),
    refine_params=(ParameterSpec("ppm", None, -5000.0, 5000.0),),
    detect="sysid.findings.variation:clock_drift_finding", build="sysid.refits:add_clock_drift",
    correct="sysid.refits:with_clock_drift", time_base=True, complete=_complete,
    auto_params=lambda p: {"ppm": p["ppm"]},
    kind="correction", figure="segments", random=_random))
