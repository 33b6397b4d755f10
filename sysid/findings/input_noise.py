"""Noise on the input channel (errors in variables): H1 biased low (effects.md, input-noise).

The two repeated sweeps share one excitation, so their aligned input difference
holds only the input channel's noise (as the ear difference gives the noise
floor). Taken as white, its one-sided density is P_n = rms^2 / (f_hi - f_lo). The
noise recording's input density S_uu then gives the input SNR and the bias of H1,
    H1 = H / (1 + S_nn / S_uu),
so the magnitude is low by 10 log10(1 + S_nn/S_uu) dB (0.41 dB at 10 dB SNR).
"""

from __future__ import annotations

import numpy as np
import scipy.signal

from ..recordings import Recording
from ..validation import VALIDATION_BAND, noise_floor
from . import DiagnosisContext, finding

__all__ = ["input_noise_finding", "input_noise_density"]

BIAS_DB = 0.1
BIAS_BAND = (20.0, 1500.0)


def input_noise_density(sweeps: list[Recording], band=VALIDATION_BAND) -> float:
    """One-sided density (FS^2/Hz) of the input channel's noise, from the repeated sweeps."""
    a, b = sweeps
    rms = noise_floor(Recording(a.u, a.u, a.fs, a.path), Recording(b.u, b.u, b.fs, b.path), band)
    return rms**2 / (band[1] - band[0])


def input_noise_finding(ctx: DiagnosisContext) -> dict:
    density = input_noise_density(ctx.sweeps)
    body = ctx.body
    f, s_uu = scipy.signal.welch(body.u - body.u.mean(), ctx.fs, nperseg=2205)
    inside = (f >= BIAS_BAND[0]) & (f <= BIAS_BAND[1])
    snr = np.maximum(s_uu[inside] - density, 1e-30) / max(density, 1e-30)
    bias = 10 * np.log10(1 + 1 / snr)
    median_bias = float(np.median(bias))
    snr_db = float(10 * np.log10(np.median(snr)))
    compensated = str(ctx.model.identification.get("estimator", "")).startswith("bias-compensated")
    significant = median_bias >= BIAS_DB and not compensated
    if significant:
        explanation = (f"the input channel carries its own noise ({np.sqrt(density * (VALIDATION_BAND[1] - VALIDATION_BAND[0])):.2e} "
                       f"FS in band, seen in the two sweeps' input difference): input SNR {snr_db:.1f} dB on the noise "
                       f"recording, so H1 and the model are biased low by {median_bias:.2f} dB "
                       f"(the FF input is itself a microphone)")
    elif compensated:
        explanation = f"input SNR {snr_db:.1f} dB; the model's estimator already compensates the H1 bias"
    else:
        explanation = f"input SNR {snr_db:.0f} dB: the H1 bias ({median_bias:.3f} dB) is negligible"
    return finding("input-noise", significant, median_bias / BIAS_DB,
                   {"input_snr_db": snr_db, "bias_db": median_bias, "input_noise_density": density},
                   explanation, "refine --add input-noise" if significant else "none", {})
