"""Noise on the input channel (errors in variables): H1 biased low (effects.md, input-noise).

The two repeated sweeps share one excitation, so their aligned input difference
holds only the input channel's noise (as the ear difference gives the noise
floor). Taken as white, its one-sided density is P_n = rms^2 / (f_hi - f_lo). The
noise recording's input density S_uu then gives the input SNR and the bias of H1,
    H1 = H / (1 + S_nn / S_uu),
so the magnitude is low by 10 log10(1 + S_nn/S_uu) dB (0.41 dB at 10 dB SNR).
The coherence of input and ear signal on the noise recording gives the SNR a second
way: gamma^2 = 1 / ((1 + S_nn/S_uu)(1 + S_ee/S_yy')), the ear's own noise density
S_ee from the noise floor (Bendat & Piersol, Random Data, 4th ed., sec. 9.2.4).

No model predicts the ear signal from the measured input better than the input's own
noise allows (errors in variables): the noise n on the measured input passes through
the path into every prediction, so the validation rms of even the true path is
    rms^2 = floor^2 + int_band |G(f)|^2 P_n df
(``input_noise_error``); the finding states that bound in multiples of the floor.
"""

from __future__ import annotations

import numpy as np
import scipy.signal

from ..core.thresholds import AT_FLOOR, VALIDATION_BAND
from ..core.thresholds import INPUT_NOISE_BIAS_BAND as BIAS_BAND
from ..core.thresholds import INPUT_NOISE_BIAS_DB as BIAS_DB
from ..core.thresholds import INPUT_NOISE_BOUND_EXCESS as BOUND_EXCESS
from ..core.thresholds import INPUT_NOISE_BOUND_SHARE as BOUND_SHARE
from ..io.recordings import Recording
from ..validation.sweeps import noise_floor
from . import DiagnosisContext, finding, uses

__all__ = ["input_noise_finding", "input_noise_density", "input_noise_error", "bound_ratio", "bound_share"]


def input_noise_density(sweeps: list[Recording], band=VALIDATION_BAND) -> float:
    """One-sided density (FS^2/Hz) of the input channel's noise, from the repeated sweeps."""
    a, b = sweeps
    rms = noise_floor(Recording(a.u, a.u, a.fs, a.path), Recording(b.u, b.u, b.fs, b.path), band)
    return rms**2 / (band[1] - band[0])


def input_noise_error(model, density: float, band=VALIDATION_BAND) -> float:
    """RMS (FS) in band of white input noise of one-sided density ``density`` (FS^2/Hz) through the
    model's linear part: sqrt(int_band |G(f)|^2 density df), on a 1 Hz grid."""
    f = np.arange(band[0], band[1] + 1.0)
    return float(np.sqrt(density * np.sum(np.abs(model.frequency_response(f)) ** 2)))


def bound_ratio(model, sweeps: list[Recording], noise_floor: float) -> float:
    """The validation rms over the floor that the input channel's noise leaves even for the true path:
    sqrt(floor^2 + e_n^2) / floor, e_n = ``input_noise_error`` (the model stands in for the path)."""
    return _over_floor(input_noise_error(model, input_noise_density(sweeps)), noise_floor)


def _over_floor(error: float, noise_floor: float) -> float:
    """sqrt(floor^2 + error^2) / floor: the floor with the input noise's error added, over the floor."""
    return float(np.hypot(noise_floor, error) / noise_floor) if noise_floor > 0 else float("inf")


def bound_share(bound: float, excess: float) -> float:
    """Share of the error power above the floor that the input noise's bound accounts for:
    (bound^2 - 1) / (excess^2 - 1), both as rms over the floor (1 when the error is at the bound or below)."""
    return 1.0 if excess <= bound else float((bound**2 - 1.0) / (excess**2 - 1.0))


def _welch_spectra(body: Recording) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(f Hz, S_uu, S_yy, S_uy) of the noise recording's body: Welch densities (FS^2/Hz), 2205-sample
    Hann segments; each once (``scipy.signal.coherence`` computed S_uu and S_yy again)."""
    f, s_uu = scipy.signal.welch(body.u, body.fs, nperseg=2205)
    _, s_yy = scipy.signal.welch(body.y, body.fs, nperseg=2205)
    _, s_uy = scipy.signal.csd(body.u, body.y, body.fs, nperseg=2205)
    return f, s_uu, s_yy, s_uy


def _coherence_snr_db(ctx: DiagnosisContext, spectra=None) -> float:
    """Median input SNR (dB) in ``BIAS_BAND`` from the coherence of the noise recording (module docstring);
    ``spectra``: its ``_welch_spectra`` when computed already."""
    f, s_uu, s_yy, s_uy = spectra or _welch_spectra(ctx.body)
    # scipy.signal.coherence: |S_uy|^2 / (S_uu S_yy) (each segment detrended, so the means do not count).
    coherence = np.abs(s_uy) ** 2 / (s_uu * s_yy)
    ear_noise = ctx.comparison.noise_floor**2 / (VALIDATION_BAND[1] - VALIDATION_BAND[0])
    inside = (f >= BIAS_BAND[0]) & (f <= BIAS_BAND[1])
    ear_part = np.maximum(s_yy[inside] - ear_noise, 1e-30) / s_yy[inside]
    # gamma^2 = SNR_in / (1 + SNR_in) * ear_part
    share = np.clip(coherence[inside] / ear_part, 1e-12, 1 - 1e-12)
    return float(10 * np.log10(np.median(share / (1 - share))))


@uses()
def input_noise_finding(ctx: DiagnosisContext) -> dict:
    density = input_noise_density(ctx.sweeps)
    spectra = _welch_spectra(ctx.body)
    f, s_uu = spectra[:2]
    inside = (f >= BIAS_BAND[0]) & (f <= BIAS_BAND[1])
    snr = np.maximum(s_uu[inside] - density, 1e-30) / max(density, 1e-30)
    bias = 10 * np.log10(1 + 1 / snr)
    median_bias = float(np.median(bias))
    snr_db = float(10 * np.log10(np.median(snr)))
    error = input_noise_error(ctx.model, density)
    bound = _over_floor(error, ctx.comparison.noise_floor)
    compensated = str(ctx.model.identification.get("estimator", "")).startswith("bias-compensated")
    biased = median_bias >= BIAS_DB and not compensated
    # The bound explains an error above the floor that no refinement removes: named while it does,
    # when the true path itself would miss the floor criterion by it (bound above AT_FLOOR).
    bounds = bound > AT_FLOOR and ctx.excess >= AT_FLOOR and bound_share(bound, ctx.excess) >= BOUND_SHARE
    significant = biased or bounds
    limit = (f"; its noise passes through the path into every prediction, so no model validates below "
             f"{bound:.1f}x the noise floor (now {ctx.excess:.1f}x): errors in variables"
             if bound >= BOUND_EXCESS else "")
    if biased:
        explanation = (f"the input channel carries its own noise ({np.sqrt(density * (VALIDATION_BAND[1] - VALIDATION_BAND[0])):.2e} "
                       f"FS in band, seen in the two sweeps' input difference): input SNR {snr_db:.1f} dB on the noise "
                       f"recording, so H1 and the model are biased low by {median_bias:.2f} dB "
                       f"(the FF input is itself a microphone){limit}")
    elif compensated:
        explanation = f"input SNR {snr_db:.1f} dB; the model's estimator already compensates the H1 bias{limit}"
    else:
        explanation = f"input SNR {snr_db:.0f} dB: the H1 bias ({median_bias:.3f} dB) is negligible{limit}"
    remedy = ("refine --add input-noise (errors-in-variables estimate); only a quieter input channel (reference "
              "microphone, its preamplifier) gets below the bound" if biased else
              "a quieter input channel (reference microphone, its preamplifier): no model gets below the bound"
              if bounds else "none")
    score = max(median_bias / BIAS_DB, bound / BOUND_EXCESS if bounds else 0.0)
    return finding("input-noise", significant, score,
                   {"input_snr_db": snr_db, "bias_db": median_bias, "input_noise_density": density,
                    "bound_ratio": bound},
                   explanation, remedy,
                   {"input_snr_coherence_db": _coherence_snr_db(ctx, spectra), "input_noise_error_fs": error,
                    "bounds_the_error": bounds})
