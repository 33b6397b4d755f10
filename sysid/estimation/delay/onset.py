"""The delay's first reading: the onset of the band-limited impulse response of a noise recording.

Converter latency and the acoustic path put d samples of pure delay in front of the
plant. A rational model of modest order imitates d samples of delay only with many
poles, so the delay is estimated first and the core is fitted on delay-compensated
data (design.md, identification step 6).

Method: the H1 estimate S_yu / S_uu of the noise recording (Welch, ``spectra``) is
weighted by a raised-cosine taper cos^2(pi f / 2 f_top) up to f_top, the highest
frequency where the (9-bin averaged) squared coherence stays above ``ONSET_COHERENCE``, and
inverted by the inverse DFT. The result is the impulse response seen through a smooth
low-pass kernel (Oppenheim & Schafer, "Discrete-Time Signal Processing", 3rd ed.,
sec. 7.5 on window tapers). The onset is the first sample whose magnitude exceeds
both ``ONSET_PEAK_FRACTION`` of the peak and ``ONSET_NOISE_MULTIPLE`` times the RMS of the
response at negative times (noise and circular wrap-around of long modes).

The kernel starts rising a few samples before the response it smooths, so the onset
is seldom later than the first non-zero sample of the true impulse response (only where
the response rises so slowly that its first samples stay below 10 % of the peak); the core
behind the delay has no direct term and adds one sample of its own, so the delay is
the onset less one: it errs short by the kernel's lead plus one, 1 to 4 samples on
most random helmets (long by 1 to 4 on 5 of 100, whose response rises slowly).
Short is the safe side: a delay estimated too long asks the core for a non-causal
response it cannot give, one too short only asks for a little more order. The kernel's
lead is a resolution limit of any threshold on a band-limited response; the model's
poles settle the rest (``sysid.estimation.delay.costs``, ``sysid.estimation.delay.walk``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...core.thresholds import ONSET_COHERENCE, ONSET_NOISE_MULTIPLE, ONSET_PEAK_FRACTION
from ...io.recordings import Recording
from ..spectra import Spectra

__all__ = ["LatencyEstimate", "estimate_latency", "compensate_delay", "SPEED_OF_SOUND", "delay_centimetres"]

SPEED_OF_SOUND = 343.0  # m/s in air at 20 degrees C


def delay_centimetres(samples: float, fs: float) -> float:
    """Sound-path length (cm) travelled in ``samples`` samples at fs Hz (0.78 cm per sample at 44.1 kHz)."""
    return 100.0 * SPEED_OF_SOUND * samples / fs


@dataclass(frozen=True)
class LatencyEstimate:
    """The estimated pure delay (samples), how it was found, and the impulse response (FS per FS, per sample)."""

    samples: int
    fs: float
    onset: int
    top_hz: float
    threshold: float
    impulse_response: np.ndarray
    # Samples added by ``refine_delay`` to the onset's estimate (None: not refined).
    refined_by: int | None = None

    @property
    def centimetres(self) -> float:
        return delay_centimetres(self.samples, self.fs)

    @property
    def lead(self) -> int:
        """The band-limited kernel's lead (samples), fs / (2 f_top) rounded up: how far short the onset may read."""
        return int(np.ceil(self.fs / (2 * self.top_hz)))

    def to_dict(self) -> dict:
        method = "onset of the band-limited H1 impulse response"
        if self.refined_by is not None:
            method += f", refined by {self.refined_by} sample(s) by the output-error cost at the model's poles"
        return {"samples": self.samples, "centimetres": round(self.centimetres, 2), "top_hz": round(self.top_hz, 1),
                "method": method}


def estimate_latency(spectra: Spectra, max_delay: int | None = None) -> LatencyEstimate:
    """Pure delay of the path from unsmoothed Welch spectra (see the module docstring).

    ``max_delay`` (samples) bounds the search; by default a quarter of the segment length.
    """
    n = spectra.nperseg
    f = spectra.frequencies
    with np.errstate(divide="ignore", invalid="ignore"):
        h1 = np.where(spectra.s_uu > 0, spectra.s_yu / spectra.s_uu, 0.0)
        coherence = np.nan_to_num(np.abs(spectra.s_yu) ** 2 / (spectra.s_uu * spectra.s_yy))
    smoothed = np.convolve(coherence, np.ones(9) / 9, mode="same")
    good = np.flatnonzero(smoothed > ONSET_COHERENCE)
    top = float(f[good[-1]]) if good.size else float(f[-1])
    top = min(max(top, 10 * f[1]), 0.45 * spectra.fs)
    taper = np.where(f <= top, np.cos(0.5 * np.pi * f / top) ** 2, 0.0)
    h = np.fft.irfft(h1 * taper, n)
    limit = n // 4 if max_delay is None else min(int(max_delay) + 1, n // 2)
    # Negative times (the second half of the circular response) hold only noise and wrap-around.
    negative = h[n // 2: n - 16]
    noise = float(np.sqrt(np.mean(negative**2))) if negative.size else 0.0
    causal = h[: n // 2]
    threshold = max(ONSET_PEAK_FRACTION * float(np.max(np.abs(causal))), ONSET_NOISE_MULTIPLE * noise)
    above = np.flatnonzero(np.abs(causal[:limit]) > threshold)
    # The smoothing kernel puts the onset zero to three samples before the true response's
    # first non-zero sample, index d + 1 for a delay d and a core without direct term (zero
    # when that first sample is large, as for the seed's FB plant). The core adds one sample
    # itself, so the delay line holds onset - 1 samples: short by the kernel's lead, never long.
    onset = int(above[0]) if above.size else 0
    samples = max(onset - 1, 0)
    return LatencyEstimate(samples, spectra.fs, onset, top, threshold, causal.copy())


def compensate_delay(recording: Recording, samples: int) -> Recording:
    """The recording with its ear signal advanced by ``samples``: u[t] against y[t + samples].

    A negative ``samples`` delays the ear signal instead (u[t - samples] against y[t]): a
    delay read too long is shortened this way.
    """
    if samples == 0:
        return recording
    if samples > 0:
        n = recording.u.size - samples
        u, y = recording.u[:n], recording.y[samples:]
    else:
        n = recording.u.size + samples
        u, y = recording.u[-samples:], recording.y[:n]
    return Recording(u, y, recording.fs, recording.path, recording.clipped_fraction, recording.dc_offset)
