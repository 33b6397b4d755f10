"""input-noise: the feed-forward input is itself a microphone; H1 is biased low (effects.md).

Simulated as white noise on the input channel at an SNR (dB) inside the excitation's
band; detected from the input noise the repeated sweeps show and H1 against H2
(``sysid.findings.input_noise``); refined by the errors-in-variables estimator
(``sysid.refits.add_input_noise``), kept unless the validation rms rises above both the
model's before and the bound the input noise sets (``sysid.findings.input_noise.bound_ratio``):
the bias it removes is one the sweeps' own input noise hides from the rms, and no model
validates below that bound, which ``refine --auto`` names when it stops there.
"""

from __future__ import annotations

from ..core.effect_spec import ParameterSpec
from .registry import Effect, register

__all__ = ["INPUT_NOISE"]


def _complete(params, ctx, before):
    if params["input_noise_density"] is None:
        from ..findings.input_noise import input_noise_density  # the detectors load when first asked
        params["input_noise_density"] = input_noise_density(ctx.sweeps)
    return params


def _random(rng):
    snr = float(rng.uniform(3, 12))
    return f"input-noise:{snr:.1f}", "input_snr_db", snr


INPUT_NOISE = register(Effect(
    name="input-noise", summary="noise on the input channel (errors in variables)",
    # Input-channel SNR (dB) inside the noise excitation's band; the noise itself is white.
    simulate_params=(ParameterSpec("snr_db", 10.0, -20.0, 80.0),),
    refine_params=(ParameterSpec("input_noise_density", None, 0.0, 1.0),),
    detect="sysid.findings.input_noise:input_noise_finding", build="sysid.refits:add_input_noise", complete=_complete,
    auto_params=lambda p: {"input_noise_density": p["input_noise_density"]}, accept="not-worse",
    figure="h1-h2", random=_random))
