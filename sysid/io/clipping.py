"""The stretches of a recording that clipping spoils, on either channel: what identification and validation leave out.

Each channel is judged by ``sysid.io.data_quality.clipped_samples`` (the ear channel also against a
model's prediction, where noise after the clipper hides the flat tops from the histogram), each
clipped run is widened by the channel's margin and the runs of both channels are merged.

A preamplifier flat-tops before mains hum or an engine order couples in, so the ear signal is
y = clip(x) + h + n: the hum h moves the flat tops by its amplitude and smears the histogram spike
at the clip level (a 50 Hz hum of 1.2e-3 FS on a preamplifier at 0.18 FS: no spike, no flat top
against the prediction). The session's lines (``sysid.io.lines.line_search``) are fitted where the
ear signal is below ``LOUD`` of its extreme and taken out first; what is left, clip(x) + n, piles
up at the clip level again (``ear_without_lines``). Used by the clipping finding
(``sysid.findings.data_quality``) and by the clipping correction of ``refine`` (``sysid.refits``).
"""

from __future__ import annotations

import numpy as np

from .data_quality import RAILS_16BIT, clipped_samples, clipped_stretches
from .lines import fit_sinusoids, quiet_samples
from .recordings import Recording

__all__ = ["EAR_MARGIN_S", "INPUT_MARGIN_S", "ear_without_lines", "channel_clipping", "clipped_spans",
           "clipped_stretches_of"]

# Margins around a clipped run left out of identification and validation: an ear sample that
# clipped spoils itself only; a clipped input misleads the model for its impulse response.
EAR_MARGIN_S = 0.002
INPUT_MARGIN_S = 0.02


def ear_without_lines(recording: Recording, predicted: np.ndarray, lines) -> np.ndarray:
    """The ear signal (FS) with the sinusoids at ``lines`` (Hz) taken out; see the module docstring.

    The sinusoids are the least-squares fit (``lines.fit_sinusoids``) to y - ``predicted`` over the
    samples where |y| is below ``LOUD`` of its largest value. Samples at the converter's rails keep
    their value: the converter clips the sum, hum included. Without lines, y itself.
    """
    y = recording.y
    if not lines:
        return y
    n = min(y.size, predicted.size)
    hum = np.zeros(y.size)
    hum[:n] = fit_sinusoids(y[:n] - predicted[:n], list(lines), recording.fs, keep=quiet_samples(y[:n]))
    at_rails = (y <= RAILS_16BIT[0]) | (y >= RAILS_16BIT[1])
    return np.where(at_rails, y, y - hum)


def channel_clipping(recording: Recording, predicted: np.ndarray | None, lines) -> dict[str, tuple]:
    """{"input" | "ear": (``data_quality.Clipping``, margin s)} of one recording; the ear's lines out first when
    ``predicted``."""
    ear = ear_without_lines(recording, predicted, lines) if predicted is not None else recording.y
    return {"input": (clipped_samples(recording.u), INPUT_MARGIN_S),
            "ear": (clipped_samples(ear, predicted=predicted), EAR_MARGIN_S)}


def clipped_spans(recording: Recording, channels: dict[str, tuple]) -> list[list[float]]:
    """The channels' clipped runs (``channel_clipping``), each widened by its margin, merged over both channels
    ([start_s, stop_s])."""
    mask = np.zeros(recording.u.size, bool)
    for clipping, margin in channels.values():
        for start, stop in clipped_stretches(clipping.mask, recording.fs, margin):
            mask[int(round(start * recording.fs)):int(round(stop * recording.fs))] = True
    return clipped_stretches(mask, recording.fs, 0.0)


def clipped_stretches_of(recording: Recording, predicted: np.ndarray | None = None, lines=()
                         ) -> tuple[list[list[float]], float]:
    """Stretches (s) of a recording to leave out for clipping on either channel, and the clipped fraction;
    ``predicted``: a model's prediction of the ear signal without lines (finds flat tops that noise hides
    from the histogram); ``lines`` (Hz): the session's lines, taken out of the ear signal first
    (``ear_without_lines``; needs ``predicted``)."""
    channels = channel_clipping(recording, predicted, lines)
    return clipped_spans(recording, channels), max(clipping.fraction for clipping, _ in channels.values())
