"""input-nonlinearity: a loudspeaker's Bl(x), Kms(x) or an amplifier, H2/H3 at -45..-30 dB (effects.md).

Simulated as a static polynomial u + a2 u^2 + a3 u^3 in front of the plant, given as
harmonic levels (dB re the fundamental) of a sine at the session's largest input;
detected by regressing the sweep residual on u^2, u^3 through the model's linear part
(``sysid.findings.nonlinearity``, after the series factors and the delay, whose
misfit it must not mistake for harmonics); refined by a Hammerstein input polynomial
(``sysid.refits.add_input_nonlinearity``).
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from .registry import Effect, register

__all__ = ["INPUT_NONLINEARITY"]


def _random(rng):
    h2 = float(rng.uniform(-45, -30))
    return f"input-nonlinearity:{h2:.1f},{rng.uniform(-45, -30):.1f}", "h2_db", h2


INPUT_NONLINEARITY = register(Effect(
    name="input-nonlinearity", summary="static input polynomial (Hammerstein): harmonics at 2f, 3f",
    simulate_params=(ParameterSpec("h2_db", -40.0, -120.0, -6.0), ParameterSpec("h3_db", -35.0, -120.0, -6.0)),
    refine_params=(ParameterSpec("degree", 3, 2, 3, "int"),),
    detect="sysid.findings.nonlinearity:nonlinearity_finding", needs=("resonance", "highpass", "lowpass", "delay"),
    build="sysid.refits:add_input_nonlinearity",
    auto_params=lambda p: {"degree": 3}, figure="harmonics", random=_random))
