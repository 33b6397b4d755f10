"""reverberant-tail: the path rings longer, on denser modes, than the model's states hold (effects.md).

Reflections inside the helmet shell and off the head and torso, a room around a dummy head,
dense high-order cavity modes: a measured path rings for tens of milliseconds above the
noise and needs tens to hundreds of states. Not simulated as a factor (a measured response
is the plant that has it: ``sysid.simulate.measured_session``); detected from the noise
recording's long impulse response against the model's (``sysid.findings.tail.tail_finding``,
asked with every other finding at hand, before under-modelled, which it leaves to what is
genuinely unexplained); refined by more states from the long estimate: its frequency-limited
truncation at the states the data need, refined by output error where affordable
(``sysid.refits.add_tail``). ``states`` is the model's order after the step; ``refine`` and
``refine --auto`` hold it to their state cap (``max_order``).
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from .registry import Effect, register

__all__ = ["REVERBERANT_TAIL"]

REVERBERANT_TAIL = register(Effect(
    name="reverberant-tail", summary="a long, dense response: more states from the long least-squares estimate",
    refine_params=(ParameterSpec("states", None, 1, 1000, "int"),),
    detect="sysid.findings.tail:tail_finding", needs_all=True, build="sysid.refits:add_tail",
    complete="sysid.refits.long_estimate:complete_states", auto_params=lambda p: {"states": p["states"]},
    figure="tail"))
