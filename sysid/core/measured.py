"""Measured acoustic responses as the true plants of synthetic sessions.

Real paths ring for tens of milliseconds and need hundreds of states, so they are
kept as what was measured: the taps of an impulse response. ``FirPlant`` simulates
a session through them (y = taps * u, the measured delay kept) and answers the few
questions a ``Model`` answers for a simulation and its truth file (``simulate``,
``frequency_response``, ``to_dict``). ``measured_response`` reads the responses this
package ships (``sysid/core/data/``, README there for their measurers and licence,
CC BY 4.0): a headphone transfer function (HD 600 on a KEMAR, 2048 taps) and a
dummy-head HRIR (FABIAN, 128 taps).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from importlib import resources

import numpy as np
import scipy.signal

from .errors import HelmetAncError

__all__ = ["FirPlant", "FIR_PLANT_FORMAT", "MEASURED_RESPONSES", "measured_response"]

FIR_PLANT_FORMAT = "helmet-anc/fir-plant@1"
MEASURED_RESPONSES = ("hptf_hd600_left", "fabian_left_az60")
_CREDIT = {
    "hptf_hd600_left": "HD 600 on KEMAR, M. Geier and V. Erbes, University of Rostock, 2014 (CC BY 4.0)",
    "fabian_left_az60": "FABIAN HRIR, F. Brinkmann et al., TU Berlin, doi:10.14279/depositonce-5718 (CC BY 4.0)",
}


@dataclass(frozen=True)
class FirPlant:
    """A path given by its impulse response ``taps`` (FS per FS, taps[0] at lag 0) at ``fs`` Hz.

    ``input_nonlinearity``: a polynomial v = a1 u + a2 u^2 + ... applied to the input first (as
    ``sysid.core.model.Model``'s), for sessions with a nonlinear drive.
    """

    taps: np.ndarray
    fs: float
    path: str = "fb"
    name: str = "measured"
    credit: str = ""
    input_nonlinearity: list | None = None
    delay: int = field(default=0, init=False)

    @property
    def length(self) -> int:
        return int(self.taps.size)

    def apply_input_nonlinearity(self, u: np.ndarray) -> np.ndarray:
        if self.input_nonlinearity is None:
            return np.asarray(u, dtype=float)
        return np.polynomial.polynomial.polyval(np.asarray(u, dtype=float), [0.0, *self.input_nonlinearity])

    def simulate(self, u: np.ndarray) -> np.ndarray:
        """The ear signal for input u (FS), from rest: the taps convolved with the (mapped) input."""
        v = self.apply_input_nonlinearity(u)
        return scipy.signal.fftconvolve(v, self.taps)[: v.size]

    def frequency_response(self, frequencies_hz) -> np.ndarray:
        z1 = np.exp(-2j * np.pi * np.asarray(frequencies_hz, dtype=float) / self.fs)
        return np.polynomial.polynomial.polyval(z1, self.taps)

    def linear(self) -> "FirPlant":
        """The same taps without the input polynomial."""
        return replace(self, input_nonlinearity=None)

    def with_factor(self, b: np.ndarray, a: np.ndarray, tolerance: float = 1e-9, max_seconds: float = 1.0) -> "FirPlant":
        """The taps through a rational factor b(z) / a(z) in series, extended until the factor's response has
        decayed below ``tolerance`` of its peak (at most ``max_seconds``)."""
        impulse = scipy.signal.lfilter(b, a, np.eye(1, int(max_seconds * self.fs), 0)[0])
        above = np.flatnonzero(np.abs(impulse) > tolerance * np.max(np.abs(impulse)))
        factor = impulse[: int(above[-1]) + 1] if above.size else impulse[:1]
        return replace(self, taps=np.convolve(self.taps, factor))

    def delayed(self, samples: int) -> "FirPlant":
        return replace(self, taps=np.concatenate((np.zeros(int(samples)), self.taps)))

    def scaled(self, gain: float) -> "FirPlant":
        return replace(self, taps=self.taps * gain)

    def to_dict(self) -> dict:
        return {"format": FIR_PLANT_FORMAT, "path": self.path, "fs": self.fs, "name": self.name, "credit": self.credit,
                "taps": self.taps.tolist(),
                "input_nonlinearity": None if self.input_nonlinearity is None
                else {"coefficients": list(self.input_nonlinearity)}}


def measured_response(name: str, path: str = "fb") -> FirPlant:
    """One of ``MEASURED_RESPONSES`` as a ``FirPlant`` of ``path`` (the README in ``sysid/core/data/`` credits it)."""
    if name not in MEASURED_RESPONSES:
        raise HelmetAncError(f"unknown measured response {name!r}; expected one of {', '.join(MEASURED_RESPONSES)}")
    with resources.files(__package__).joinpath("data", "measured_responses.npz").open("rb") as handle:
        data = np.load(handle)
        taps = np.asarray(data[name], dtype=float)
        fs = float(data[name + "__fs"])
    return FirPlant(taps, fs, path, name, _CREDIT[name])
