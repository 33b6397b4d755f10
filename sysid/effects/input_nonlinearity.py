"""input-nonlinearity: a loudspeaker's Bl(x), Kms(x) or an amplifier, H2/H3 at -45..-30 dB (effects.md).

Simulated as a static polynomial u + a2 u^2 + a3 u^3 in front of the plant, given as
harmonic levels (dB re the fundamental) of a sine at the session's largest input (a3 > 0, an expanding
map such as a softening suspension's, or with ``compressive=1`` a3 < 0, a hardening one's), or with
``tanh=1`` as a saturating driver s tanh((u + o)/s) - s tanh(o/s) (a soft clipper, asymmetric by
its offset o) whose levels hold at the sweeps' amplitude (``saturation``); with ``prefilter_hz`` > 0
behind a high-pass of that corner (Hz) and order ``prefilter_order`` (a coupling capacitor in front of
the part that distorts: a Wiener-Hammerstein driver, the model form's ``prefilter``), the levels
those of a sine in its pass band;
detected by regressing the sweep residual on u^2, u^3 through the model's linear part
(``sysid.findings.nonlinearity``, after the series factors and the delay, whose
misfit it must not mistake for harmonics), the harmonics also measured on exponential
sweeps (Farina); refined by a Hammerstein input map fitted together with the core
(``sysid.refits.add_input_nonlinearity``: a polynomial of degree up to ``degree`` chosen by
description length, or a tanh saturation, whichever validates better; behind a high-pass whose
corner is fitted with them where the static map leaves the model above the floor:
``sysid.estimation.wiener_hammerstein``).
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from .registry import Effect, register

__all__ = ["INPUT_NONLINEARITY", "saturation"]


def saturation(params: dict, sweep_amplitude: float) -> dict:
    """The truth record of a saturating driver (``tanh=1``): its form (``sysid.core.model``) of harmonic levels
    ``h2_db``, ``h3_db`` at the sweeps' input amplitude (FS), which ``reference_amplitude`` records."""
    from ..estimation.input_nonlinearity import saturation_form

    return {"coefficients": None, "form": saturation_form(params["h3_db"], params["h2_db"], sweep_amplitude),
            "reference_amplitude": float(sweep_amplitude)}


def _random(rng):
    h2 = float(rng.uniform(-45, -30))
    return f"input-nonlinearity:{h2:.1f},{rng.uniform(-45, -30):.1f}", "h2_db", h2


INPUT_NONLINEARITY = register(Effect(
    name="input-nonlinearity", summary="static input polynomial (Hammerstein): harmonics at 2f, 3f",
    simulate_params=(ParameterSpec("h2_db", -40.0, -120.0, -6.0), ParameterSpec("h3_db", -35.0, -120.0, -6.0),
                     ParameterSpec("tanh", 0, 0, 1, "int"), ParameterSpec("prefilter_hz", 0.0, 0.0, 5000.0),
                     ParameterSpec("prefilter_order", 1, 1, 2, "int"), ParameterSpec("compressive", 0, 0, 1, "int")),
    refine_params=(ParameterSpec("degree", 7, 2, 7, "int"),),
    detect="sysid.findings.nonlinearity:nonlinearity_finding",
    needs=("resonance", "highpass", "lowpass", "delay", "clipping"),
    build="sysid.refits:add_input_nonlinearity",
    auto_params=lambda p: {"degree": 7}, figure="harmonics", random=_random))
