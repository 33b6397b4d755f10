"""dc-offset: a preamplifier offset or microphone bias on a channel (effects.md).

Simulated as a constant added to one channel (FS units); detected from the means of
the recordings and, on the ear channel, from the silence before each sweep
(``sysid.findings.data_quality.dc_offset_finding``); corrected by the model's
``output_offset`` (``sysid.refits.add_dc_offset``), judged on the full-band rms.
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from ..core.errors import IdentificationError
from .registry import Effect, register

__all__ = ["DC_OFFSET"]


def _complete(params, ctx, before):
    if params["offset_fs"] is None:
        from ..findings.data_quality import dc_offset_finding  # the detectors load when first asked
        params["offset_fs"] = dc_offset_finding(ctx)["params"]["ear_offset_fs"]
        if not params["offset_fs"]:
            raise IdentificationError("--add dc-offset: the sweeps show no ear-channel offset; give dc-offset:OFFSET_FS")
    return params


def _random(rng):
    level = float(rng.uniform(0.003, 0.03) * rng.choice([-1, 1]))
    return f"dc-offset:{level:.4f}", "ear_offset_fs", level


DC_OFFSET = register(Effect(
    name="dc-offset", summary="offset of a channel (FS): preamplifier offset, microphone bias",
    simulate_params=(ParameterSpec("level", 0.01, -0.5, 0.5), ParameterSpec("channel", 1, 0, 1, "int")),
    refine_params=(ParameterSpec("offset_fs", None, -1.0, 1.0),),
    detect="sysid.findings.data_quality:dc_offset_finding", build="sysid.refits:add_dc_offset",
    correct="sysid.refits:with_dc_offset", complete=_complete,
    auto_params=lambda p: {"offset_fs": p["ear_offset_fs"]}, kind="correction", accept="full-band",
    figure="levels", random=_random))
