"""A Wiener-Hammerstein model's pre-filter corner fitted with its static map and core by output error.

The model is y = L(f(P_c u)) + e: P_c a high-pass of corner c (Hz) and order 1 or 2 in front of the
static map f (a driver's coupling capacitor or DC-blocking stage ahead of the part that distorts;
``sysid.core.model``, the form's ``prefilter``), L the delay and core. A pre-filter in front of a linear
path is only a factor the core can take in; in front of a nonlinearity it is not: the harmonics and
intermodulation products of f are made from P_c u, so the corner is identifiable from them alone, and
the criterion is the same output error as the Hammerstein fit's (``sysid.estimation.hammerstein``).

The corner is one more output-error parameter, fitted by variable projection: for each c the map and
the core are refined together with P_c held (``fit_hammerstein(prefilter=...)``), which leaves a cost
V(c) in one variable. V is read on a logarithmic grid of corners for either order (the start: the
data's own minimum, with no prior on the corner), then minimised in ln c by Brent's method between the
grid neighbours of the best (Brent, "Algorithms for Minimization without Derivatives", 1973, ch. 5),
on short fits (two rounds, a cubic map); the minimum of each order is fitted in full, and the corner of
the lower cost found again by Brent on full fits within 15 % of it. The minimum is sharp (a random
helmet's FB path behind a 20 Hz first-order high-pass, H2 -15 dB: V at 12.6 and 23.9 Hz 31 % and 12 %
above V at 20 Hz, the validation error 97x and 78x the floor against 1.0x), so every corner of the grid
is read; and the short fits' minimum lies a few per cent off (19.3 Hz at H2 -20 dB, where the full fit
validates at 1.64x against 1.04x at 20 Hz), so the full fits have the last word.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.optimize

from ..core.model import Model
from ..core.thresholds import IDENTIFICATION_BAND
from ..io.recordings import Recording
from .hammerstein import MAX_DEGREE, HammersteinFit, fit_hammerstein

__all__ = ["fit_wiener_hammerstein", "PREFILTER_CORNERS_HZ"]

# The grid of the corner's start (Hz): coupling high-passes from 1 Hz to the low end of the
# identification band and beyond (a corner well inside the band is a factor the data show plainly).
PREFILTER_CORNERS_HZ = tuple(float(c) for c in np.geomspace(1.0, 160.0, 9))
# The grid's fits take fewer alternation rounds than the final one: they rank corners, not refine them.
_GRID_ROUNDS = 2
# Brent's search stops within this relative step of the corner (ln c to 0.03: 3 %).
_CORNER_TOLERANCE = 0.03
# The final search on full fits: within 15 % of the short fits' corner, to 0.5 %.
_FINE_SPAN = 0.15
_FINE_TOLERANCE = 0.005


def _highpass(corner_hz: float, order: int) -> dict:
    return {"kind": "highpass", "order": int(order), "corner_hz": float(corner_hz)}


def fit_wiener_hammerstein(model: Model, noise: Recording, kind: str = "polynomial", seconds: float = 2.0,
                           core_seconds: float | None = None, transient_s: float = 0.0, band=IDENTIFICATION_BAND,
                           max_degree: int = MAX_DEGREE, corners_hz=PREFILTER_CORNERS_HZ,
                           orders=(1, 2), keep: np.ndarray | None = None) -> HammersteinFit:
    """The high-pass pre-filter (corner in ``corners_hz``' span, order in ``orders``), the static map of
    ``kind`` and the core of ``model`` fitted together on ``noise`` (see the module docstring; the arguments
    as ``fit_hammerstein``'s, ``keep`` its samples that count). The fit's ``form`` carries the pre-filter; its ``parameters`` count the corner.
    Corners at or above the band's upper edge are left out (a pre-filter there removes the excitation)."""
    corners = [c for c in corners_hz if c < 0.5 * band[1]]

    def fit(corner, order, **cheap):
        arguments = {"seconds": seconds, "core_seconds": core_seconds, "max_degree": max_degree, **cheap}
        return fit_hammerstein(model, noise, kind, transient_s=transient_s, band=band,
                               prefilter=_highpass(corner, order), keep=keep, **arguments)

    def cost(corner, order):
        # The search ranks corners: a short stretch, two rounds and a cubic map do that at a fraction of the time.
        try:
            return fit(corner, order, rounds=_GRID_ROUNDS, max_degree=min(max_degree, 3),
                       core_seconds=min(core_seconds or seconds, seconds)).cost_after
        except (ValueError, np.linalg.LinAlgError):
            return math.inf

    found = []
    for order in orders:
        grid = [cost(corner, order) for corner in corners]
        best = int(np.argmin(grid))
        low, high = (math.log(corners[max(best - 1, 0)]), math.log(corners[min(best + 1, len(corners) - 1)]))
        minimum = scipy.optimize.minimize_scalar(lambda x: cost(math.exp(x), order), bounds=(low, high),
                                                 method="bounded", options={"xatol": _CORNER_TOLERANCE})
        found.append((minimum.fun, math.exp(minimum.x), order) if minimum.fun <= grid[best]
                     else (grid[best], corners[best], order))
    # The order of the lower full cost; its corner refined by Brent again on full fits (the short fits' minimum
    # lies a few per cent off, and the validation error is that sensitive: see the module docstring).
    _, corner, order = min(((fit(c, o).cost_after, c, o) for _, c, o in sorted(found)[:2]))
    bounds = (math.log(corner) - _FINE_SPAN, math.log(corner) + _FINE_SPAN)
    fine = scipy.optimize.minimize_scalar(lambda x: fit(math.exp(x), order).cost_after, bounds=bounds,
                                          method="bounded", options={"xatol": _FINE_TOLERANCE})
    return fit(math.exp(fine.x), order)
