"""clipping: a converter or preamplifier that flat-tops, at full scale or below it (effects.md).

Simulated as an ear channel whose clean peak is ``peak`` times the clip ``level`` (FS);
detected as flat tops at any level on either channel and a histogram spike at the clip
level (``sysid.io.data_quality``, ``sysid.findings.data_quality.clipping_finding``);
corrected by leaving the clipped stretches out of identification and validation
(the model's ``excluded``; ``sysid.refits.add_clipping``). The correction is kept unless the
validation error rises (``accept="not-worse"``): the clipped samples hold the clipper's error,
not the path's, and where only the noise recording clips (a path whose DC gain turns a driver's
u^2 into a DC that reaches the rails; the sweeps stay below them) leaving them out changes no
validation figure until the structure they hid (the input map, fitted on the kept samples only)
is modelled.
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from .registry import Effect, register

__all__ = ["CLIPPING"]


def _random(rng):
    return f"clipping:{rng.uniform(1.1, 1.6):.2f},{rng.choice([1.0, rng.uniform(0.1, 0.6)]):.2f}", None, None


CLIPPING = register(Effect(
    name="clipping", summary="flat tops of a channel at the converter's rails or a preamplifier's clip level",
    # Clean ear-signal peak relative to the clip level; a preamplifier flat-tops at level (FS),
    # the 16-bit converter at 1.
    simulate_params=(ParameterSpec("peak", 1.3, 1.0, 8.0), ParameterSpec("level", 1.0, 0.01, 1.0)),
    refine_params=(), detect="sysid.findings.data_quality:clipping_finding", build="sysid.refits:add_clipping",
    correct="sysid.refits:with_clipping", auto_params=lambda p: {}, accept="not-worse",
    kind="correction", figure="levels", random=_random))
