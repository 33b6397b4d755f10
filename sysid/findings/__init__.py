"""Detectors of the physical effects a model misses, one module per family of effects.

Each detector takes a ``DiagnosisContext`` (the model, the recordings, the
comparison on the sweeps and the findings of the detectors it needs) and returns
``Finding`` records; ``Finding.to_dict`` is the entry of design.md's diagnosis JSON
``{"effect", "significant", "score", "params", "explanation", "remedy", "evidence"}``. ``score`` is the detector's statistic divided by its
significance threshold, so a finding is significant when its score reaches 1
(and its other conditions hold); scores of different detectors rank findings.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..compare import Comparison
from ..model import Model
from ..recordings import Recording
from ..thresholds import TRANSIENT_S

__all__ = ["DiagnosisContext", "Finding", "finding", "linear_part", "noise_prediction", "SPEED_OF_SOUND"]

SPEED_OF_SOUND = 343.0  # m/s in air at 20 degC


@dataclass
class DiagnosisContext:
    """Everything the detectors share; ``body`` is the noise recording after its transient."""

    model: Model
    noise: Recording
    sweeps: list[Recording]
    comparison: Comparison
    transient_s: float = TRANSIENT_S
    # The findings of the detectors run so far (``diagnose`` runs a detector after those of the
    # effects it declares it needs: ``sysid.effects.Effect.needs``).
    findings: list = field(default_factory=list)
    cache: dict = field(default_factory=dict)

    @property
    def fs(self) -> float:
        return self.model.fs

    @property
    def body(self) -> Recording:
        return self.noise.trimmed(self.transient_s)

    @property
    def excess(self) -> float:
        """Validation rms over the noise floor."""
        return self.comparison.ratio


def _plain(value):
    """A JSON-safe plain-Python value (numpy scalars and tuples converted, non-finite floats to None)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, (np.bool_,)):
        return bool(value)
    return value


@dataclass
class Finding:
    """One finding of ``diagnose``: the entry of the ``helmet-anc/diagnosis@1`` JSON (design.md).

    ``score`` is the detector's statistic over its significance threshold (significant
    from 1, other conditions permitting); ``params`` the effect's estimates in the units
    their names carry; ``evidence`` the figures the decision rests on. ``finding["effect"]``
    reads a field as the JSON dict's key does, for readers of the dict contract.
    """

    effect: str
    significant: bool
    score: float
    params: dict
    explanation: str
    remedy: str
    evidence: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}

    @classmethod
    def from_dict(cls, data: dict) -> "Finding":
        """The record of a JSON dict; a missing ``evidence`` is empty, other fields are required."""
        missing = [name for name in ("effect", "significant", "score", "params", "explanation", "remedy")
                   if name not in data]
        if missing:
            raise ValueError(f"finding lacks {', '.join(missing)}")
        return finding(data["effect"], data["significant"], data["score"], data["params"], data["explanation"],
                       data["remedy"], data.get("evidence"))

    def __getitem__(self, key: str):
        if key not in self.__dataclass_fields__:
            raise KeyError(key)
        return getattr(self, key)

    def __setitem__(self, key: str, value) -> None:
        if key not in self.__dataclass_fields__:
            raise KeyError(key)
        setattr(self, key, value)

    def __contains__(self, key: str) -> bool:
        return key in self.__dataclass_fields__

    def get(self, key: str, default=None):
        return getattr(self, key) if key in self.__dataclass_fields__ else default


def finding(effect: str, significant: bool, score: float, params: dict, explanation: str, remedy: str,
            evidence: dict | None = None) -> Finding:
    """A ``Finding`` with plain-Python (JSON-safe) values."""
    return Finding(effect, bool(significant), float(score) if np.isfinite(score) else 0.0,
                   {k: _plain(v) for k, v in params.items()}, explanation, remedy,
                   {k: _plain(v) for k, v in (evidence or {}).items()})


def noise_prediction(ctx: DiagnosisContext) -> np.ndarray:
    """The model's prediction of the whole noise recording's ear signal (FS), computed once per context."""
    if "noise_prediction" not in ctx.cache:
        ctx.cache["noise_prediction"] = ctx.model.simulate(ctx.noise.u)
    return ctx.cache["noise_prediction"]


def linear_part(model: Model) -> Model:
    """The model without its input polynomial and disturbance (delay and LTI core only)."""
    return Model(path=model.path, fs=model.fs, A=model.A, B=model.B, C=model.C, D=model.D, delay=model.delay)
