"""How far a model may be from the true path: the relative 95 % bound |S - S_model| / |S_model|.

From the model's ``uncertainty`` field (``{"frequencies_hz", "relative_95"}``, design.md
"The model") when present, interpolated in log frequency; else a documented default:
``DEFAULT_IN_BAND`` (20 %) inside the band the model was identified and validated on
(its ``identification["band_hz"]``, else 20 Hz - 5 kHz).

Where nothing is known of S the bound comes from what the model vouches for instead:
outside the stated band (below its first / above its last frequency; the model there is an
extrapolation: DC, below the sweeps, above the noise's cut-off) and where the stated bound
reaches ``LINEARISATION_LIMIT`` (100 %: the band is a first-order, delta-method bound, which
stops being one when the error is as large as the response; on random helmets a missed
low-frequency mode hid 3.4 times |S_model| under a stated 1.08). Vouched gains are
v(f') = (1 + r95) |S_model| at the frequencies f' where r95 < the limit. The only
assumption is that the path's gain grows no faster than 1/f going down from any vouched
frequency (at most one integrator-like pole below the band: the seed's FB path has a pole
at 0.9999 and 30 times its 20 Hz gain at DC) and does not exceed the largest vouched gain
above it:

.. math::
    B(f) = \\max_{f'} v(f') \\max(1, f' / f),

With an unknown phase that gives |S - S_model| <= |S_model| + B, i.e. the relative bound
1 + B(f) / |S_model(f)|, so a robust design keeps |Q| <= 0.5 / (|S_model| + B) there: it
does (almost) nothing. A relative bound of 100 % (the former rule outside the band) did not
cover a truth with the model's magnitude and the opposite phase, nor the seed's FB path at
a few hertz under a model that missed its delay (20 times |S_model|).

A model without an uncertainty field whose own validation error is more than
``MAX_VALIDATION_RATIO`` (3) times the sweeps' noise floor (``identification["rms"]`` and
``["noise_floor"]``) is refused: its error is then dominated by what it misses, which
no default bound describes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sysid.core.errors import HelmetAncError
from sysid.core.model import Model
from sysid.core.thresholds import IDENTIFICATION_BAND

__all__ = ["Uncertainty", "model_uncertainty", "stated_band", "DEFAULT_IN_BAND", "OUTSIDE_BAND", "LINEARISATION_LIMIT",
           "MAX_VALIDATION_RATIO"]

DEFAULT_IN_BAND = 0.2
# Where nothing is known and there is no model to take a peak from (``Uncertainty`` built by hand).
OUTSIDE_BAND = 1.0
LINEARISATION_LIMIT = 1.0
# Frequencies (log-spaced, plus DC) on which the peak-based bound is tabulated.
_UNKNOWN_POINTS = 4000
MAX_VALIDATION_RATIO = 3.0


@dataclass(frozen=True)
class Uncertainty:
    """Relative 95 % bound on a grid; ``band_hz`` where it is stated; ``source`` says from where.

    ``unknown_hz`` / ``unknown_95``: the bound 1 + B / |S_model| (module docstring)
    tabulated in log frequency; ``peak`` the largest vouched gain, used outside ``band_hz`` and where the stated
    bound reaches ``LINEARISATION_LIMIT``; without it (None) the bound there is ``OUTSIDE_BAND``.
    """

    frequencies_hz: np.ndarray
    relative_95: np.ndarray
    band_hz: tuple[float, float]
    source: str
    unknown_hz: np.ndarray | None = None
    unknown_95: np.ndarray | None = None
    peak: float | None = None

    def stated(self, frequencies_hz) -> np.ndarray:
        """The stated bound alone (log-frequency interpolation; NaN outside band_hz)."""
        f = np.asarray(frequencies_hz, dtype=float)
        values = np.interp(_log(f), _log(self.frequencies_hz), self.relative_95)
        return np.where((f < self.band_hz[0]) | (f > self.band_hz[1]), np.nan, values)

    def unknown(self, frequencies_hz) -> np.ndarray:
        """Where nothing is known: outside band_hz or a stated bound at or above LINEARISATION_LIMIT."""
        values = self.stated(frequencies_hz)
        return ~(values < LINEARISATION_LIMIT)

    def at(self, frequencies_hz) -> np.ndarray:
        """The bound at frequencies in Hz: the stated one where it holds, else the peak-based one."""
        f = np.asarray(frequencies_hz, dtype=float)
        values = self.stated(f)
        if self.unknown_hz is None:
            fallback = np.full(f.shape, OUTSIDE_BAND)
        else:
            fallback = np.exp(np.interp(_log(f), _log(self.unknown_hz), np.log(self.unknown_95)))
        return np.where(values < LINEARISATION_LIMIT, values, np.fmax(values, fallback))

    def to_dict(self) -> dict:
        return {"frequencies_hz": [float(v) for v in self.frequencies_hz],
                "relative_95": [float(v) for v in self.relative_95], "band_hz": list(self.band_hz), "source": self.source,
                "peak": self.peak, "linearisation_limit": LINEARISATION_LIMIT}


def _log(f) -> np.ndarray:
    return np.log(np.maximum(np.asarray(f, dtype=float), 1e-3))


def _with_peak(model: Model, base: Uncertainty) -> Uncertainty:
    """``base`` with the bound 1 + B / |S_model| where nothing is known (module docstring)."""
    f = np.concatenate(([0.0], np.geomspace(0.1, model.fs / 2.0, _UNKNOWN_POINTS)))
    magnitude = np.abs(model.frequency_response(f))
    stated = base.stated(f)
    vouched = np.where(stated < LINEARISATION_LIMIT, (1.0 + stated) * magnitude, 0.0)
    if not np.any(vouched > 0.0):
        # Nothing vouched for at all: twice the largest in-band (else any) gain, flat.
        inside = ~np.isnan(stated)
        vouched = np.full(f.shape, 2.0 * float(np.max(magnitude[inside] if np.any(inside) else magnitude)))
    # B(f) = max(max_{f' > f} v f' / f, max_{f' <= f} v): a suffix maximum and a prefix maximum.
    above = np.maximum.accumulate((vouched * f)[::-1])[::-1] / np.maximum(f, 0.1)
    below = np.maximum.accumulate(vouched)
    bound = np.maximum(above, below)
    relative = 1.0 + bound / np.maximum(magnitude, 1e-12 * float(bound.max()))
    return Uncertainty(base.frequencies_hz, base.relative_95, base.band_hz, base.source, f, relative,
                       float(np.max(vouched)))


def _stated_field(model: Model) -> dict | None:
    stated = getattr(model, "uncertainty", None)
    if stated is None and isinstance(model.identification, dict):
        stated = model.identification.get("uncertainty")
    return stated or None


def stated_band(model: Model) -> tuple[float, float]:
    """(lowest, highest) frequency in Hz the model is vouched for: its uncertainty field's range, else
    its identification band, else ``sysid.core.thresholds.IDENTIFICATION_BAND`` (``model_uncertainty``'s band)."""
    stated = _stated_field(model)
    if stated:
        f = np.asarray(stated["frequencies_hz"], dtype=float)
        return float(f.min()), float(f.max())
    if isinstance(model.identification, dict) and model.identification.get("band_hz"):
        return tuple(float(v) for v in model.identification["band_hz"])
    return tuple(float(v) for v in IDENTIFICATION_BAND)


def model_uncertainty(model: Model) -> Uncertainty:
    """The uncertainty a design must respect for ``model`` (module docstring)."""
    stated = _stated_field(model)
    if stated:
        f = np.asarray(stated["frequencies_hz"], dtype=float)
        r = np.asarray(stated["relative_95"], dtype=float)
        # A non-finite entry (a failed covariance) states nothing: the bound where nothing is known.
        r = np.where(np.isfinite(r), r, LINEARISATION_LIMIT)
        order = np.argsort(f)
        return _with_peak(model, Uncertainty(f[order], np.maximum(r[order], 0.0), (float(f.min()), float(f.max())),
                                             "the model's uncertainty field"))
    info = model.identification if isinstance(model.identification, dict) else {}
    rms, floor = info.get("rms"), info.get("noise_floor")
    if rms is not None and floor and rms > MAX_VALIDATION_RATIO * floor:
        raise HelmetAncError(f"the {model.path.upper()} model validates at {rms / floor:.1f}x the noise floor "
                             f"(above {MAX_VALIDATION_RATIO:g}x) and states no uncertainty band: its error is unknown, "
                             "so no controller can be guaranteed stable with it; diagnose and refine it first")
    band = stated_band(model)
    f = np.array(band, dtype=float)
    return _with_peak(model, Uncertainty(f, np.full(2, DEFAULT_IN_BAND), (float(band[0]), float(band[1])),
                                         f"default {DEFAULT_IN_BAND:.0%} inside the identification band (no uncertainty field)"))
