"""time-variation: helmet fit and leak that change, mostly below 200-300 Hz (effects.md).

Simulated as a gain change below corner_hz (a linear change over the session, or a
step before sweep 1 or 2: the helmet re-seated between recordings); detected inside
the noise recording (halves against interleaved segments) and across recordings
(``sysid.findings.variation.time_variation_finding``). No single model holds a path
that changes: it is reported, and the user identifies per condition.
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from .registry import Effect, register

__all__ = ["TIME_VARIATION"]


def _random(rng):
    return f"time-variation:{rng.uniform(2, 5) * rng.choice([-1, 1]):.1f},200,{int(rng.integers(0, 3))}", None, None


TIME_VARIATION = register(Effect(
    name="time-variation", summary="a path that changes while or between recordings",
    # Gain change below corner_hz from the start to the end of the session (a changing leak).
    # step 0: a linear change over the session; step k = 1 or 2: the change happens at once before sweep k.
    simulate_params=(ParameterSpec("change_db", 3.0, -20.0, 20.0), ParameterSpec("corner_hz", 200.0, 10.0, 2000.0),
                     ParameterSpec("step", 0, 0, 2, "int")),
    # The between-recordings test stands aside on clipped recordings (the clipping finding says which).
    detect="sysid.findings.variation:time_variation_finding", needs=("clipping",),
    not_refinable="a path that changes while recording has no single model; identify per condition",
    kind="report", figure="segments", random=_random))
