"""The controller JSON (format helmet-anc/controller@1, design.md "Control"; binding).

``{"format", "fs", "internal_model", "ff", "fb", "latency_samples", "bands_hz",
"predicted_attenuation_db": {"ff", "fb", "both"}}`` plus fields of ours, all optional on read
(older files load with them empty): ``margins`` (``phase_margin_deg`` null where the loop gain never
crosses 1, ``crossovers`` their count), ``coherence_bound_db``, ``predicted_overall_dba``, ``notes``,
``provenance`` (which models, which spectrum, which options, the orders, the design's CPU time),
``limits`` (per band of ``bands_hz``, dB, positive = quieter at the ear, null where not computed:
``causal_ff_db`` the causal Wiener feed-forward bound, ``causal_ff_ruled_db`` the same within the
design's rules (``anc.ruled_bound``), ``coherence_db`` the coherence bound,
``feedback_db`` the robust feedback bound, and ``reasons`` {"ff": [...], "fb": [...]}: what limits
each band in words, "" where no single cause is named) and ``feedback_bound`` (the feedback bound's
own record, ``anc.feedback_bound.FeedbackBound.to_dict``). Drive:
y[k] = W x[k-L] + Q d_hat[k-L], d_hat = e - S_model y, with W = ``ff`` and Q = ``fb``,
discrete state-space filters at ``fs`` that carry their own sign (None = off).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field

import numpy as np

from sysid.core import lti
from sysid.core.errors import HelmetAncError
from sysid.core.files import atomic_write_text
from sysid.core.model import Model

__all__ = ["CONTROLLER_FORMAT", "BOARD_LATENCY_SAMPLES", "StateSpaceFilter", "Controller"]

CONTROLLER_FORMAT = "helmet-anc/controller@1"
# The board's control path (firmware/anc_control.h): capture, compute and play take 2 samples, so
# a controller for the board has latency_samples >= 2. The one place of this figure: the design's
# default latency and codegen's check (``codegen.controller.PROCESSING_LATENCY_MIN``) read it.
BOARD_LATENCY_SAMPLES = 2
_PARTS = ("ff", "fb", "both")


@dataclass(frozen=True)
class StateSpaceFilter:
    """x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k]; single input, single output."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray

    @classmethod
    def from_dict(cls, data, name: str) -> "StateSpaceFilter":
        if not isinstance(data, dict) or set("ABCD") - set(data):
            raise HelmetAncError(f"controller field {name!r} must be null or an object with A, B, C, D")
        try:
            A = np.array(data["A"], dtype=float) if np.size(data["A"]) else np.zeros((0, 0))
            n = A.shape[0]
            A = A.reshape(n, n)
            B = np.array(data["B"], dtype=float).reshape(n, 1)
            C = np.array(data["C"], dtype=float).reshape(1, n)
            D = np.array(data["D"], dtype=float).reshape(1, 1)
        except (TypeError, ValueError):
            raise HelmetAncError(f"controller field {name!r}: A must be n x n, B n x 1, C 1 x n, D 1 x 1") from None
        if not all(np.all(np.isfinite(m)) for m in (A, B, C, D)):
            raise HelmetAncError(f"controller field {name!r} holds non-finite numbers")
        filt = cls(A, B, C, D)
        if filt.order and lti.spectral_radius(A) >= 1.0:
            raise HelmetAncError(f"controller field {name!r} is unstable (largest pole radius "
                                 f"{lti.spectral_radius(A):.6f}); design it again")
        return filt

    @property
    def order(self) -> int:
        return int(self.A.shape[0])

    def to_dict(self) -> dict:
        return {k: np.asarray(getattr(self, k)).tolist() for k in "ABCD"}

    def frequency_response(self, frequencies_hz, fs: float) -> np.ndarray:
        z = np.exp(2j * np.pi * np.asarray(frequencies_hz, dtype=float) / fs)
        if not self.order:
            return np.full(z.shape, float(self.D[0, 0]), dtype=complex)
        return lti.frequency_response(self.A, self.B, self.C, self.D, z)

    def simulate(self, u: np.ndarray) -> np.ndarray:
        if not self.order:
            return float(self.D[0, 0]) * np.asarray(u, dtype=float)
        return lti.simulate(self.A, self.B, self.C, self.D, np.asarray(u, dtype=float))


def _finite(data):
    """Plain JSON of nested dicts and lists: non-finite numbers as null (JSON has no NaN)."""
    if isinstance(data, dict):
        return {k: _finite(v) for k, v in data.items()}
    if isinstance(data, (list, tuple)):
        return [_finite(v) for v in data]
    if isinstance(data, (float, np.floating)):
        return float(data) if math.isfinite(data) else None
    if isinstance(data, np.integer):
        return int(data)
    return data


def _limits(data) -> dict | None:
    """The optional ``limits`` field as read: None, or per-band lists as long as ``bands_hz``."""
    if data is None:
        return None
    if not isinstance(data, dict) or not isinstance(data.get("bands_hz"), list):
        raise HelmetAncError("controller field 'limits' must be null or an object with bands_hz")
    n = len(data["bands_hz"])
    for key in ("causal_ff_db", "causal_ff_ruled_db", "coherence_db", "feedback_db"):
        values = data.get(key, [None] * n)
        if not isinstance(values, list) or len(values) != n:
            raise HelmetAncError(f"controller field 'limits': {key} must hold one value per band ({n})")
    return data


@dataclass
class Controller:
    """A designed controller; ``to_dict``/``from_dict`` are the JSON contract (module docstring)."""

    fs: float
    internal_model: Model
    ff: StateSpaceFilter | None
    fb: StateSpaceFilter | None
    latency_samples: int
    bands_hz: list[float]
    predicted_attenuation_db: dict[str, list[float]]
    margins: dict = field(default_factory=dict)
    coherence_bound_db: list[float] | None = None
    predicted_overall_dba: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    provenance: dict = field(default_factory=dict)
    limits: dict | None = None
    feedback_bound: dict | None = None

    def __post_init__(self):
        if not (isinstance(self.latency_samples, (int, np.integer)) and self.latency_samples >= 1):
            raise HelmetAncError(f"latency_samples must be a whole number >= 1; found {self.latency_samples!r}")
        if not (math.isfinite(float(self.fs)) and float(self.fs) == self.internal_model.fs):
            raise HelmetAncError(f"controller fs {self.fs} differs from its internal model's {self.internal_model.fs}")
        missing = [p for p in _PARTS if p not in self.predicted_attenuation_db]
        if missing:
            raise HelmetAncError(f"predicted_attenuation_db lacks {', '.join(missing)}")
        for part in _PARTS:
            if len(self.predicted_attenuation_db[part]) != len(self.bands_hz):
                raise HelmetAncError(f"predicted_attenuation_db[{part!r}] has {len(self.predicted_attenuation_db[part])} "
                                     f"values for {len(self.bands_hz)} bands")

    def to_dict(self) -> dict:
        def clean(values):
            return [None if v is None or not math.isfinite(v) else float(v) for v in values]

        return {
            "format": CONTROLLER_FORMAT,
            "fs": float(self.fs),
            "internal_model": self.internal_model.to_dict(),
            "ff": None if self.ff is None else self.ff.to_dict(),
            "fb": None if self.fb is None else self.fb.to_dict(),
            "latency_samples": int(self.latency_samples),
            "bands_hz": [float(b) for b in self.bands_hz],
            "predicted_attenuation_db": {p: clean(self.predicted_attenuation_db[p]) for p in _PARTS},
            "margins": self.margins,
            "coherence_bound_db": None if self.coherence_bound_db is None else clean(self.coherence_bound_db),
            "predicted_overall_dba": self.predicted_overall_dba,
            "notes": list(self.notes),
            "provenance": self.provenance,
            "limits": _finite(self.limits),
            "feedback_bound": _finite(self.feedback_bound),
        }

    @classmethod
    def from_dict(cls, data: dict) -> "Controller":
        if not isinstance(data, dict) or data.get("format") != CONTROLLER_FORMAT:
            found = data.get("format") if isinstance(data, dict) else type(data).__name__
            raise HelmetAncError(f"not a controller file: format must be {CONTROLLER_FORMAT!r}; found {found!r}")
        for key in ("fs", "internal_model", "ff", "fb", "latency_samples", "bands_hz", "predicted_attenuation_db"):
            if key not in data:
                raise HelmetAncError(f"controller file lacks the field {key!r}")
        return cls(
            fs=float(data["fs"]),
            internal_model=Model.from_dict(data["internal_model"]),
            ff=None if data["ff"] is None else StateSpaceFilter.from_dict(data["ff"], "ff"),
            fb=None if data["fb"] is None else StateSpaceFilter.from_dict(data["fb"], "fb"),
            latency_samples=data["latency_samples"],
            bands_hz=list(data["bands_hz"]),
            predicted_attenuation_db={p: [np.nan if v is None else v for v in data["predicted_attenuation_db"].get(p, [])]
                                      for p in _PARTS},
            margins=data.get("margins", {}),
            coherence_bound_db=data.get("coherence_bound_db"),
            predicted_overall_dba=data.get("predicted_overall_dba", {}),
            notes=list(data.get("notes", [])),
            provenance=data.get("provenance", {}),
            limits=_limits(data.get("limits")),
            feedback_bound=data.get("feedback_bound"),
        )

    def save(self, path: str | os.PathLike) -> None:
        atomic_write_text(path, json.dumps(self.to_dict(), indent=1) + "\n")

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Controller":
        try:
            with open(path, encoding="utf-8") as handle:
                data = json.load(handle)
        except (OSError, ValueError) as exc:
            raise HelmetAncError(f"{path}: cannot read the controller ({exc})") from None
        return cls.from_dict(data)
