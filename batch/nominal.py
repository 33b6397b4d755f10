"""A nominal model and a multiplicative uncertainty bound for one helmet (one path).

The members are the models of one helmet's path identified on several heads and fits.
For robust control the helmet needs one model H_n and a bound w(f) such that every
head's true response lies in {H_n (1 + Delta w) : |Delta| <= 1} (Skogestad &
Postlethwaite, Multivariable Feedback Control, 2nd ed., section 7.4.1, multiplicative
uncertainty), i.e.

.. math::  |H_{true}(f) - H_n(f)| / |H_n(f)| \\le w(f).

1. Nominal response: the mean of the members' complex logarithms,
   H_0 = exp(mean_i (ln|H_i| + j arg H_i)) with each phase unwrapped along frequency:
   a geometric mean of the magnitudes and a mean phase, which does not cancel when
   members' phases differ (an arithmetic mean of the complex responses would).
2. Low-order model of H_0: the frequency-domain subspace method (``sysid.estimation.subspace``,
   McKelvey, Akcay & Ljung 1996) on H_0 z^d (d the members' smallest delay), weighted
   by 1/|H_0| so the fit is relative, for each order up to a few above the members';
   every member's own model is a candidate too. The lowest order whose mean bound is
   within ``ORDER_TOLERANCE`` of the smallest is kept.
3. Bound: w(f) = max_i (|H_i - H_n| + r_i |H_i|) / |H_n|, with r_i a member's own 95 %
   relative band (its ``uncertainty``, when it has one): by the triangle inequality it
   covers every member's true response wherever the members' bands do.

Frequencies: ``BOUND_POINTS`` log-spaced from 20 Hz to 5 kHz (the identification band;
outside it the members are not constrained by any data).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sysid.core.errors import HelmetAncError
from sysid.core.model import Model
from sysid.core.thresholds import IDENTIFICATION_BAND
from sysid.estimation.subspace import SubspaceDecomposition

__all__ = ["NominalModel", "nominal_model", "member_band", "BOUND_POINTS", "ORDER_TOLERANCE"]

BOUND_POINTS = 300
# Keep the lowest order whose mean bound is within this fraction of the best order's.
ORDER_TOLERANCE = 0.05
# Orders tried above the largest member order.
EXTRA_ORDERS = 4


@dataclass
class NominalModel:
    """A helmet's nominal model, its bound and what it was made from."""

    model: Model
    frequencies_hz: np.ndarray
    relative_bound: np.ndarray
    member_responses: np.ndarray  # (members, frequencies)
    nominal_response: np.ndarray  # H_0 of step 1 (before the low-order fit)
    members: list[str] = field(default_factory=list)
    candidates: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        """The model JSON (helmet-anc/model@1) with its ``uncertainty``."""
        data = self.model.to_dict()
        data["uncertainty"] = {"frequencies_hz": self.frequencies_hz.tolist(), "relative_95": self.relative_bound.tolist()}
        return data

    def coverage(self, responses) -> np.ndarray:
        """Fraction of frequencies where each given response (rows) lies inside the bound."""
        responses = np.atleast_2d(responses)
        nominal = self.model.frequency_response(self.frequencies_hz)
        distance = np.abs(responses - nominal[None, :]) / np.abs(nominal)[None, :]
        return np.mean(distance <= self.relative_bound[None, :], axis=1)


def member_band(model: Model, frequencies_hz: np.ndarray) -> np.ndarray:
    """A member's own 95 % relative band at frequencies_hz (zero when it has none)."""
    band = model.to_dict().get("uncertainty")
    if not band:
        return np.zeros_like(frequencies_hz)
    f = np.asarray(band["frequencies_hz"], dtype=float)
    r = np.asarray(band["relative_95"], dtype=float)
    # Outside the band's own frequencies hold its end values (np.interp's rule), never extrapolate.
    return np.interp(frequencies_hz, f, r)


def _log_mean(responses: np.ndarray) -> np.ndarray:
    """Step 1: exp of the mean complex logarithm, phases unwrapped on one branch."""
    phases = np.unwrap(np.angle(responses), axis=1)
    # Put every member on the first member's branch at the lowest frequency.
    phases -= 2 * np.pi * np.round((phases[:, :1] - phases[:1, :1]) / (2 * np.pi))
    log_magnitude = np.log(np.abs(responses))
    return np.exp(log_magnitude.mean(axis=0) + 1j * phases.mean(axis=0))


def _bound(nominal: np.ndarray, responses: np.ndarray, bands: np.ndarray) -> np.ndarray:
    """Step 3: max over members of (|H_i - H_n| + r_i |H_i|) / |H_n|."""
    spread = np.abs(responses - nominal[None, :]) + bands * np.abs(responses)
    return spread.max(axis=0) / np.abs(nominal)


def nominal_model(models: list[Model], names: list[str] | None = None, points: int = BOUND_POINTS,
                  band: tuple[float, float] = IDENTIFICATION_BAND) -> NominalModel:
    """Nominal model and multiplicative bound of one helmet's path from its members' models."""
    if len(models) < 2:
        raise HelmetAncError(f"a nominal model needs at least two members; found {len(models)}")
    fs, path = models[0].fs, models[0].path
    for model in models[1:]:
        if model.fs != fs or model.path != path:
            raise HelmetAncError(f"members must share path and sample rate; found {path}/{fs:g} Hz and "
                                 f"{model.path}/{model.fs:g} Hz")
    names = names or [f"member {k + 1}" for k in range(len(models))]
    f = np.geomspace(band[0], band[1], points)
    responses = np.array([m.frequency_response(f) for m in models])
    bands = np.array([member_band(m, f) for m in models])
    target = _log_mean(responses)

    delay = min(m.delay for m in models)
    z = np.exp(2j * np.pi * f / fs)
    omega = 2 * np.pi * f / fs
    max_order = min(max(m.order for m in models) + EXTRA_ORDERS, 24)
    decomposition = SubspaceDecomposition(omega, target * z**delay, q=max(30, max_order + 2),
                                          noise_variance=np.abs(target) ** 2)
    candidates = []
    for order in range(1, max_order + 1):
        fit = decomposition.fit_if_stable(order)
        if fit is None:
            continue
        model = Model(path=path, fs=fs, A=fit.A, B=fit.B, C=fit.C, D=fit.D, delay=delay)
        candidates.append((f"subspace fit of the nominal response, order {order}", model))
    for name, member in zip(names, models):
        core = Model(path=path, fs=fs, A=member.A, B=member.B, C=member.C, D=member.D, delay=member.delay)
        candidates.append((f"member {name}", core))
    scored = []
    for source, model in candidates:
        w = _bound(model.frequency_response(f), responses, bands)
        scored.append({"source": source, "order": model.order, "mean_bound": float(np.mean(w)),
                       "max_bound": float(np.max(w)), "model": model, "bound": w})
    best = min(entry["mean_bound"] for entry in scored)
    chosen = min((e for e in scored if e["mean_bound"] <= best * (1 + ORDER_TOLERANCE)),
                 key=lambda e: (e["order"], e["mean_bound"]))
    model = chosen["model"]
    model.identification = {
        "method": "nominal of a helmet's members: mean complex log response, low-order fit, multiplicative bound",
        "source": chosen["source"], "members": list(names), "band_hz": list(band),
        "mean_relative_bound": chosen["mean_bound"], "max_relative_bound": chosen["max_bound"],
        "members_with_own_band": int(np.count_nonzero(bands.any(axis=1))),
    }
    table = [{k: v for k, v in e.items() if k not in ("model", "bound")} for e in scored]
    return NominalModel(model, f, chosen["bound"], responses, target, list(names), table)

