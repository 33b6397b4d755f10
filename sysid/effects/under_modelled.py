"""under-modelled: an order too low for the dynamics in band (effects.md).

Not simulated (any effect a nominal-order model cannot hold shows as it); asked
last, with every other finding at hand (``sysid.findings.under_modelled``): error
above the floor that one more mode removes, and in any case error above twice the
floor that nothing named explains; refined by more order (``sysid.refits.add_order``).
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from .registry import Effect, register

__all__ = ["UNDER_MODELLED"]

UNDER_MODELLED = register(Effect(
    name="under-modelled", summary="too low an order for the dynamics in band",
    refine_params=(ParameterSpec("extra_order", 2, 1, 8, "int"),),
    detect="sysid.findings.under_modelled:under_modelled_finding", needs_all=True, build="sysid.refits:add_order",
    auto_params=lambda p: {"extra_order": 2}))
