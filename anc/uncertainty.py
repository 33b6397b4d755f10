"""How far a model may be from the true path: the relative 95 % bound |S - S_model| / |S_model|.

From the model's ``uncertainty`` field (``{"frequencies_hz", "relative_95"}``, design.md
"The model") when present, interpolated in log frequency; else a documented default:
``DEFAULT_IN_BAND`` (20 %) inside the band the model was identified and validated on
(its ``identification["band_hz"]``, else 20 Hz - 5 kHz). Outside the stated band (below
the first / above the last frequency of the field, or outside the identification band)
nothing is known, and the bound is ``OUTSIDE_BAND`` (100 %): a robust design then keeps
|S_model Q| <= 0.5 there, i.e. does (almost) nothing.

A model without an uncertainty field whose own validation error is more than
``MAX_VALIDATION_RATIO`` (3) times the sweeps' noise floor (``identification["rms"]`` and
``["noise_floor"]``) is refused: its error is then dominated by what it misses, which
no default bound describes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sysid.errors import HelmetAncError
from sysid.identify import IDENTIFICATION_BAND
from sysid.model import Model

__all__ = ["Uncertainty", "model_uncertainty", "DEFAULT_IN_BAND", "OUTSIDE_BAND", "MAX_VALIDATION_RATIO"]

DEFAULT_IN_BAND = 0.2
OUTSIDE_BAND = 1.0
MAX_VALIDATION_RATIO = 3.0


@dataclass(frozen=True)
class Uncertainty:
    """Relative 95 % bound on a grid; ``band_hz`` where it is stated; ``source`` says from where."""

    frequencies_hz: np.ndarray
    relative_95: np.ndarray
    band_hz: tuple[float, float]
    source: str

    def at(self, frequencies_hz) -> np.ndarray:
        """The bound at frequencies in Hz (log-frequency interpolation; OUTSIDE_BAND beyond band_hz)."""
        f = np.asarray(frequencies_hz, dtype=float)
        logf = np.log(np.maximum(f, 1e-3))
        values = np.interp(logf, np.log(np.maximum(self.frequencies_hz, 1e-3)), self.relative_95)
        outside = (f < self.band_hz[0]) | (f > self.band_hz[1])
        return np.where(outside, OUTSIDE_BAND, values)

    def to_dict(self) -> dict:
        return {"frequencies_hz": [float(v) for v in self.frequencies_hz],
                "relative_95": [float(v) for v in self.relative_95], "band_hz": list(self.band_hz), "source": self.source}


def model_uncertainty(model: Model) -> Uncertainty:
    """The uncertainty a design must respect for ``model`` (module docstring)."""
    stated = getattr(model, "uncertainty", None)
    if stated is None and isinstance(model.identification, dict):
        stated = model.identification.get("uncertainty")
    if stated:
        f = np.asarray(stated["frequencies_hz"], dtype=float)
        r = np.asarray(stated["relative_95"], dtype=float)
        order = np.argsort(f)
        return Uncertainty(f[order], np.maximum(r[order], 0.0), (float(f.min()), float(f.max())),
                           "the model's uncertainty field")
    info = model.identification if isinstance(model.identification, dict) else {}
    rms, floor = info.get("rms"), info.get("noise_floor")
    if rms is not None and floor and rms > MAX_VALIDATION_RATIO * floor:
        raise HelmetAncError(f"the {model.path.upper()} model validates at {rms / floor:.1f}x the noise floor "
                             f"(above {MAX_VALIDATION_RATIO:g}x) and states no uncertainty band: its error is unknown, "
                             "so no controller can be guaranteed stable with it; diagnose and refine it first")
    band = IDENTIFICATION_BAND
    if isinstance(model.identification, dict) and model.identification.get("band_hz"):
        band = tuple(float(v) for v in model.identification["band_hz"])
    f = np.array(band, dtype=float)
    return Uncertainty(f, np.full(2, DEFAULT_IN_BAND), (float(band[0]), float(band[1])),
                       f"default {DEFAULT_IN_BAND:.0%} inside the identification band (no uncertainty field)")
