"""periodic-disturbance: mains hum, engine orders - lines in the ear signal not in the input (effects.md).

Simulated as sinusoids at k * frequency_hz (k = 1..harmonics) at level / k (FS rms);
detected as residual lines absent from the input (``sysid.findings.disturbance``);
modelled as a disturbance (sinusoids fitted per recording and removed before the fit),
not a part of the plant (``sysid.refits.add_periodic_disturbance``). Identification already
takes the session's lines out of the recordings it fits and validates on, and out of the noise
floor (``sysid.io.lines``, ``sysid.validation.sweeps.without_repeat_lines``): the model's core is not bent
toward them, and its error against the raw sweeps, the hum, stands above the floor for this
finding to name.
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from ..core.errors import IdentificationError
from .registry import Effect, register

__all__ = ["PERIODIC_DISTURBANCE"]


def _complete(params, ctx, before):
    if params["frequencies_hz"] is None:
        from ..findings.disturbance import disturbance_finding  # the detectors load when first asked
        found = disturbance_finding(ctx)["params"]["frequencies_hz"]
        if not found:
            raise IdentificationError("--add periodic-disturbance: no line found in the residual; "
                                      "give periodic-disturbance:frequencies_hz=F1/F2")
        params["frequencies_hz"] = tuple(found)
    return params


def _random(rng):
    f = float(rng.choice([50.0, 60.0, 41.7]))
    return f"periodic-disturbance:{f},3,{rng.uniform(3e-4, 2e-3):.2e}", "frequencies_hz", f


PERIODIC_DISTURBANCE = register(Effect(
    name="periodic-disturbance", summary="sinusoidal lines in the ear signal that the input does not drive",
    # Lines at k * frequency_hz, k = 1..harmonics, RMS level / k (FS) each.
    simulate_params=(ParameterSpec("frequency_hz", 50.0, 1.0, 22000.0), ParameterSpec("harmonics", 3, 1, 40, "int"),
                     ParameterSpec("level", 1e-3, 0.0, 0.5)),
    refine_params=(ParameterSpec("frequencies_hz", None, 1.0, 22000.0, "list"),),
    detect="sysid.findings.disturbance:disturbance_finding", needs=("resonance", "highpass", "lowpass"),
    build="sysid.refits:add_periodic_disturbance",
    complete=_complete, auto_params=lambda p: {"frequencies_hz": tuple(p["frequencies_hz"])},
    kind="disturbance", figure="lines", random=_random))
