"""lowpass: an anti-alias or reconstruction filter, a microphone's roll-off (effects.md).

Simulated as a first- or second-order Butterworth low-pass (corner in Hz) in series
with the plant; detected with the other series factors (``sysid.findings.dynamics``);
refined by the factor in series in front of the core (``sysid.refits.add_lowpass``).
"""

from __future__ import annotations

import numpy as np

from ..core.effect_spec import ParameterSpec
from ..core.structures import factor_coefficients
from .registry import Effect, register
from .series import complete_factor

__all__ = ["LOWPASS"]


def _random(rng):
    corner = float(np.exp(rng.uniform(np.log(1000.0), np.log(16000.0))))
    return f"lowpass:{corner:.0f},{int(rng.integers(1, 3))}", "corner_hz", corner


LOWPASS = register(Effect(
    name="lowpass", summary="first/second-order Butterworth low-pass, corner in Hz",
    simulate_params=(ParameterSpec("corner_hz", 2500.0, 50.0, 22000.0), ParameterSpec("order", 2, 1, 2, "int")),
    refine_params=(ParameterSpec("corner_hz", None, 50.0, 22000.0), ParameterSpec("order", 2, 1, 2, "int")),
    detect="sysid.findings.dynamics:dynamics_findings", build="sysid.refits:add_lowpass",
    complete=complete_factor("lowpass", "corner_hz"),
    auto_params=lambda p: {"corner_hz": p["corner_hz"], "order": p["order"]},
    factor=lambda params, fs: factor_coefficients("lowpass", params, fs), figure="series-factor", random=_random))
