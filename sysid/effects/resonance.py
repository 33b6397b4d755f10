"""resonance: a mode the model lacks - ear-canal quarter wave, helmet cavity (effects.md).

Simulated as a peaking biquad (f0 in Hz, Q, gain in dB) in series with the plant
(``sysid.core.structures``); detected by fitting the series factor families to the sweeps
(``sysid.findings.dynamics.dynamics_findings``, which judges resonance, high-pass and
low-pass together and keeps at most one); refined by the peaking factor in series
(gain given) or by one more mode started at f0, Q (``sysid.refits.add_resonance``).
"""

from __future__ import annotations

import numpy as np

from ..core.effect_spec import ParameterSpec
from ..core.structures import factor_coefficients
from .registry import Effect, register
from .series import complete_factor

__all__ = ["RESONANCE"]


def _random(rng):
    f0 = float(np.exp(rng.uniform(np.log(60.0), np.log(3600.0))))
    return f"resonance:{f0:.1f},{rng.uniform(3, 15):.2f},{rng.uniform(6, 14) * rng.choice([1, 1, -1]):.2f}", "f0_hz", f0


RESONANCE = register(Effect(
    name="resonance", summary="a lightly damped mode: peaking factor at f0 (Hz) with Q and gain (dB)",
    simulate_params=(ParameterSpec("f0_hz", 3400.0, 20.0, 22000.0), ParameterSpec("q", 8.0, 0.5, 200.0),
                     ParameterSpec("gain_db", 10.0, -30.0, 30.0)),
    refine_params=(ParameterSpec("f0_hz", None, 20.0, 22000.0), ParameterSpec("q", 10.0, 0.5, 200.0),
                   ParameterSpec("gain_db", None, -30.0, 30.0)),
    detect="sysid.findings.dynamics:dynamics_findings", build="sysid.refits:add_resonance",
    complete=complete_factor("resonance", "f0_hz"),
    auto_params=lambda p: {"f0_hz": p["f0_hz"], "q": p["q"], "gain_db": p["gain_db"]},
    factor=lambda params, fs: factor_coefficients("resonance", params, fs), figure="series-factor", random=_random))
