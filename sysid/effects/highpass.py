"""highpass: a MEMS microphone's roll-off or a codec's DC-removal filter (effects.md).

Simulated as a first- or second-order high-pass (corner in Hz) in series with the
plant; detected with the other series factors (``sysid.findings.dynamics``); refined
by the factor in series in front of the core (``sysid.refits.add_highpass``).
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from ..core.structures import factor_coefficients
from .registry import Effect, register
from .series import complete_factor

__all__ = ["HIGHPASS"]


def _random(rng):
    corner = float(rng.uniform(10.0, 80.0))
    return f"highpass:{corner:.1f},{int(rng.integers(1, 3))}", "corner_hz", corner


HIGHPASS = register(Effect(
    name="highpass", summary="first/second-order high-pass, corner in Hz",
    simulate_params=(ParameterSpec("corner_hz", 60.0, 1.0, 5000.0), ParameterSpec("order", 1, 1, 2, "int")),
    refine_params=(ParameterSpec("corner_hz", None, 1.0, 5000.0), ParameterSpec("order", 1, 1, 2, "int")),
    detect="sysid.findings.dynamics:dynamics_findings", build="sysid.refits:add_highpass",
    complete=complete_factor("highpass", "corner_hz"),
    auto_params=lambda p: {"corner_hz": p["corner_hz"], "order": p["order"]},
    factor=lambda params, fs: factor_coefficients("highpass", params, fs), figure="series-factor", random=_random))
