"""delay: converter latency and sound path, 1 sample = 22.7 us = 0.78 cm at 44.1 kHz (effects.md).

Simulated as more samples of pure delay in front of the plant; detected by a scan of
the delay with the model's poles fixed (``sysid.findings.delay.delay_finding``, which
settles a tie with a series factor, so it runs after them); refined by a longer delay
line and the core re-identified behind it (``sysid.refits.add_delay``).
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from ..core.errors import IdentificationError
from .registry import Effect, register

__all__ = ["DELAY"]


def _complete(params, ctx, before):
    if params["samples"] is None:
        from ..findings.delay import scan_delay  # the detectors load when first asked
        best, _ = scan_delay(ctx)
        if best <= ctx.model.delay:
            raise IdentificationError("--add delay: the data show no delay beyond the model's; give delay:SAMPLES")
        params["samples"] = best - ctx.model.delay
    return params


def _random(rng):
    d = int(rng.integers(5, 50))
    return f"delay:{d}", "samples", d


DELAY = register(Effect(
    name="delay", summary="pure delay in samples: converter latency, sound path",
    simulate_params=(ParameterSpec("samples", 23, 1, 2000, "int"),),
    refine_params=(ParameterSpec("samples", None, 1, 2000, "int"),),
    detect="sysid.findings.delay:delay_finding", needs=("resonance", "highpass", "lowpass"),
    build="sysid.refits:add_delay", complete=_complete,
    auto_params=lambda p: {"samples": p["samples"]}, figure="delay-scan", random=_random))
