"""Shared look of the report's figures: sizes, colours, axis helpers.

Figures are created with ``matplotlib.figure.Figure`` directly (no pyplot state), so
they render with the Agg canvas in any process and never open a window.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

__all__ = ["COLORS", "db", "log_frequency_axis", "mark_band", "new_figure", "phase_on_branch"]

# Colours name what a curve is, the same in every figure.
COLORS = {
    "measured": "0.55",
    "noisy": "0.7",
    "smoothed": "tab:blue",
    "model": "tab:red",
    "seed": "tab:orange",
    "noise_floor": "tab:green",
    "bound": "tab:purple",
    "frequency": "tab:brown",
    "highlight": "gold",
}

_DEFAULT_WIDTH_IN = 8.0


def new_figure(rows: int = 1, cols: int = 1, height: float = 3.2, width: float = _DEFAULT_WIDTH_IN,
               sharex: bool = False, dpi: float = 100.0, **grid) -> tuple[Figure, np.ndarray]:
    """A Figure of width x (rows * height) inches and its axes as a flat array."""
    figure = Figure(figsize=(width, height * rows), dpi=dpi, layout="constrained")
    axes = figure.subplots(rows, cols, sharex=sharex, squeeze=False, **grid)
    return figure, axes.ravel()


def db(x) -> np.ndarray:
    """20 log10 |x| in dB, with -inf where x is zero."""
    with np.errstate(divide="ignore"):
        return 20.0 * np.log10(np.abs(x))


def log_frequency_axis(ax, band: tuple[float, float], label: bool = True) -> None:
    """Logarithmic frequency axis over band (Hz) with a light grid."""
    ax.set_xscale("log")
    ax.set_xlim(band)
    ax.grid(True, which="both", alpha=0.3)
    if label:
        ax.set_xlabel("frequency (Hz)")


def phase_on_branch(response: np.ndarray, reference_deg: np.ndarray) -> np.ndarray:
    """Phase of response in degrees, on the 360-degree branch nearest reference_deg.

    Lets a noisy estimate be drawn against a smooth, unwrapped model phase: where the
    estimate's own phase cannot be unwrapped reliably it still lands next to the model.
    """
    raw = np.angle(response, deg=True)
    return reference_deg + (raw - reference_deg + 180.0) % 360.0 - 180.0


def mark_band(ax, low: float, high: float, label: str | None = None) -> None:
    """Shade a frequency band (Hz) on ax."""
    ax.axvspan(low, high, color=COLORS["highlight"], alpha=0.25, label=label)
