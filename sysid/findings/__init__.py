"""Detectors of the physical effects a model misses, one module per family of effects.

Each detector takes a ``DiagnosisContext`` (the model, the recordings and the
comparison on the sweeps) and returns finding dicts with the contract of
design.md: ``{"effect", "significant", "score", "params", "explanation",
"remedy", "evidence"}``. ``score`` is the detector's statistic divided by its
significance threshold, so a finding is significant when its score reaches 1
(and its other conditions hold); scores of different detectors rank findings.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..compare import Comparison
from ..model import Model
from ..recordings import Recording

__all__ = ["DiagnosisContext", "finding", "linear_part", "SPEED_OF_SOUND"]

SPEED_OF_SOUND = 343.0  # m/s in air at 20 degC


@dataclass
class DiagnosisContext:
    """Everything the detectors share; ``body`` is the noise recording after its transient."""

    model: Model
    noise: Recording
    sweeps: list[Recording]
    comparison: Comparison
    transient_s: float = 3.0
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


def finding(effect: str, significant: bool, score: float, params: dict, explanation: str, remedy: str,
            evidence: dict | None = None) -> dict:
    """A finding dict with plain-Python (JSON-safe) values."""
    def plain(value):
        if isinstance(value, (list, tuple)):
            return [plain(v) for v in value]
        if isinstance(value, (np.integer,)):
            return int(value)
        if isinstance(value, (np.floating, float)):
            return float(value) if np.isfinite(value) else None
        if isinstance(value, (np.bool_,)):
            return bool(value)
        return value

    return {"effect": effect, "significant": bool(significant), "score": float(score) if np.isfinite(score) else 0.0,
            "params": {k: plain(v) for k, v in params.items()}, "explanation": explanation, "remedy": remedy,
            "evidence": {k: plain(v) for k, v in (evidence or {}).items()}}


def linear_part(model: Model) -> Model:
    """The model without its input polynomial and disturbance (delay and LTI core only)."""
    return Model(path=model.path, fs=model.fs, A=model.A, B=model.B, C=model.C, D=model.D, delay=model.delay)
