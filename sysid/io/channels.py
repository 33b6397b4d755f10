"""Which channel is the input: swapped input and ear channels detected by causality.

The ear signal is the input after the sound path, so it lags the input: the phase of
the frequency response H(f) = S_uy(f) / S_uu(f) from input to ear falls with
frequency, by the path's latency and the delay of its dynamics. With the channels
swapped the estimate is 1/H, whose phase rises by as much: the "ear" leads the
"input", which no sound path does. The measure is the mean group delay over the band
where the channels are coherent (magnitude-squared coherence above ``COHERENT``,
100 Hz-4 kHz: the sweeps' band less its lowest octaves, where a high-pass leaves
little coherence), the coherence-weighted least-squares slope

.. math:: \\tau = -\\frac{d\\varphi(\\omega)}{d\\omega}

of the unwrapped phase of H against angular frequency in rad/sample, so tau is in samples.

Measured on sessions of the appendix-A plants (seeds 0-1) and of random helmet paths
(``sysid.random_plant``, seeds 0-40, both paths; noise, 1-2 s sweeps; see
tests/test_sysid/io/test_channels.py and BENCHMARKS.md): in the right order tau is 1.7 to 74 samples,
swapped it is -1.7 to -74. The channels are called swapped when tau is at most
``-LEAD_SAMPLES``; the order is unclear (a warning) when |tau| is below it: a path with
no latency and no lag, a pure gain, looks the same both ways round.

Silent and unrelated ear channels are refused where recordings are read
(``sysid.io.recordings``, by ``sysid.io.ear_channel``); this check needs both channels
coherent. The tunables (``SEGMENT``, ``BAND_HZ``, ``COHERENT``, ``MIN_BINS``,
``LEAD_SAMPLES``, ``EXCERPT_S``) are ``sysid.core.thresholds``' ``CHANNEL_ORDER_*``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.signal

from ..core.errors import RecordingError
from ..core.thresholds import CHANNEL_ORDER_BAND_HZ as BAND_HZ
from ..core.thresholds import CHANNEL_ORDER_COHERENT as COHERENT
from ..core.thresholds import CHANNEL_ORDER_EXCERPT_S as EXCERPT_S
from ..core.thresholds import CHANNEL_ORDER_LEAD_SAMPLES as LEAD_SAMPLES
from ..core.thresholds import CHANNEL_ORDER_MIN_BINS as MIN_BINS
from ..core.thresholds import CHANNEL_ORDER_SEGMENT as SEGMENT
from .recordings import RecordingWarning

__all__ = ["ChannelOrder", "channel_order", "check_channel_order", "ChannelOrderWarning", "EXCERPT_S", "LEAD_SAMPLES",
           "COHERENT"]


class ChannelOrderWarning(RecordingWarning):
    """The channel order of a recording cannot be told from its samples (the ear does not clearly lag)."""


@dataclass(frozen=True)
class ChannelOrder:
    """The direction measures of one recording (see the module docstring).

    ``group_delay`` is the mean group delay from input to ear channel in samples
    (positive: the ear lags), ``bins`` the number of coherent frequency bins used.
    """

    group_delay: float
    bins: int

    @property
    def judged(self) -> bool:
        return self.bins >= MIN_BINS

    @property
    def swapped(self) -> bool:
        """The ear channel leads the input channel."""
        return self.judged and self.group_delay <= -LEAD_SAMPLES

    @property
    def clear(self) -> bool:
        """The ear channel lags the input channel (the right order)."""
        return self.judged and self.group_delay >= LEAD_SAMPLES


def channel_order(u: np.ndarray, y: np.ndarray, fs: float) -> ChannelOrder:
    """Direction measures of input ``u`` and ear signal ``y`` (full-scale units, ``fs`` Hz)."""
    n = min(u.size, y.size, int(EXCERPT_S * fs))
    u, y = np.asarray(u[:n], dtype=float), np.asarray(y[:n], dtype=float)
    if n < 4 * SEGMENT:
        return ChannelOrder(0.0, 0)
    f, s_uu = scipy.signal.welch(u, fs, nperseg=SEGMENT)
    _, s_yy = scipy.signal.welch(y, fs, nperseg=SEGMENT)
    _, s_uy = scipy.signal.csd(u, y, fs, nperseg=SEGMENT)  # scipy: E[conj(U) Y], so H = s_uy / s_uu
    with np.errstate(divide="ignore", invalid="ignore"):
        coherence = np.abs(s_uy) ** 2 / (s_uu * s_yy)
        response = s_uy / s_uu
    band = (f >= BAND_HZ[0]) & (f <= min(BAND_HZ[1], 0.45 * fs)) & (coherence > COHERENT) & np.isfinite(response)
    bins = np.flatnonzero(band)
    if bins.size < MIN_BINS:
        return ChannelOrder(0.0, int(bins.size))
    omega = 2.0 * np.pi * f[bins] / fs  # rad/sample
    phase = np.unwrap(np.angle(response[bins]))
    slope = np.polyfit(omega, phase, 1, w=coherence[bins])[0]
    return ChannelOrder(float(-slope), int(bins.size))


def check_channel_order(u: np.ndarray, y: np.ndarray, fs: float, name: str, input_channel: int = 0,
                        output_channel: int = 1) -> ChannelOrder:
    """RecordingError when the ear channel leads the input (swapped channels); a warning when unclear.

    ``name`` (the file) and the channel numbers go into the one-line message, with the fix.
    """
    order = channel_order(u, y, fs)
    if order.swapped:
        raise RecordingError(
            f"{name}: channel {output_channel} (taken as the ear) leads channel {input_channel} (taken as the input) "
            f"by {-order.group_delay:.0f} samples, which no sound path does: the channels look swapped; "
            f"give --input-channel {output_channel} --output-channel {input_channel}")
    if order.judged and not order.clear:
        warnings.warn(f"{name}: channel {output_channel} (taken as the ear) does not clearly lag channel "
                      f"{input_channel} (taken as the input) (mean group delay {order.group_delay:.1f} samples); "
                      "if the model is poor, check the order with --input-channel/--output-channel", ChannelOrderWarning, stacklevel=2)
    return order
