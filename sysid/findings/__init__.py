"""Detectors of the physical effects a model misses, one module per family of effects.

Each detector takes a ``DiagnosisContext`` (the model, the recordings, the
comparison on the sweeps, the findings of the effects it declares it needs and the
shared values it declares it reads) and returns ``Finding`` records; ``Finding.to_dict`` is the entry of design.md's diagnosis JSON
``{"effect", "significant", "score", "params", "explanation", "remedy", "evidence"}``. ``score`` is the detector's statistic divided by its
significance threshold, so a finding is significant when its score reaches 1
(and its other conditions hold); scores of different detectors rank findings.

Shared values: what several detectors read (the model's prediction of the noise
recording, the session's line search, the segments' responses) is computed once per
context by a named provider (``provider``), a function of the context's model,
recordings and comparison only, never of findings, so no detector's result depends on
which detector asked first. A detector declares the values it reads (``uses``), and
``diagnose`` lets it read those only (``DiagnosisContext.value``). Findings likewise: a
detector reads those of the effects its effect declares it needs (``sysid.effects.Effect.needs``;
every finding for ``needs_all``) through ``DiagnosisContext.finding`` and ``findings_of``,
which refuse any other, so what it sees does not depend on which detectors happened to run
before it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..core.model import Model
from ..core.thresholds import TRANSIENT_S
from ..io.recordings import Recording
from ..validation.compare import Comparison

__all__ = ["DiagnosisContext", "Finding", "finding", "linear_part", "noise_prediction", "PROVIDERS", "provider", "uses"]

# The shared values' providers by name: provider(ctx) -> value.
PROVIDERS: dict[str, Callable] = {}


def provider(name: str):
    """Register the decorated ``function(ctx)`` as the provider of the shared value ``name``."""
    def register(function: Callable) -> Callable:
        PROVIDERS[name] = function
        return function
    return register


def uses(*names: str):
    """Declare the shared values the decorated detector reads (its ``uses`` attribute)."""
    def declare(detector: Callable) -> Callable:
        detector.uses = tuple(names)
        return detector
    return declare


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
    # The shared values computed so far (``value``), and the names the running detector declared
    # (``diagnose`` sets them around each detector; None: any, for a context used outside diagnose).
    values: dict = field(default_factory=dict)
    readable: tuple[str, ...] | None = None
    # The effects whose findings the running detector may read (``finding``; ``diagnose`` sets them
    # around each detector; None: any, for a detector that reads every finding and outside diagnose).
    readable_findings: tuple[str, ...] | None = None

    def value(self, name: str):
        """The shared value ``name``, computed by its provider (``PROVIDERS``) once per context."""
        if self.readable is not None and name not in self.readable:
            raise KeyError(f"shared value {name!r} is read by a detector that does not declare it (findings.uses)")
        if name not in self.values:
            if name not in PROVIDERS:
                raise KeyError(f"no provider of the shared value {name!r}")
            # A provider reads other shared values freely: they too are functions of the inputs alone.
            readable, self.readable = self.readable, None
            try:
                self.values[name] = PROVIDERS[name](self)
            finally:
                self.readable = readable
        return self.values[name]

    def findings_of(self, *effects: str) -> list:
        """The findings so far of the named effects, in the order they were found; each effect must be
        one the running detector declares it needs (``readable_findings``)."""
        if self.readable_findings is not None:
            undeclared = [name for name in effects if name not in self.readable_findings]
            if undeclared:
                declared = ", ".join(self.readable_findings) or "none"
                raise KeyError(f"the finding of {undeclared[0]!r} is read by a detector that does not declare it "
                               f"(sysid.effects.Effect.needs); it declares {declared}")
        return [f for f in self.findings if f["effect"] in effects]

    def finding(self, effect: str):
        """The finding of ``effect`` (one the running detector declares it needs), or None when there is none."""
        return next(iter(self.findings_of(effect)), None)

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


@provider("noise-prediction")
def _predict_noise(ctx: DiagnosisContext) -> np.ndarray:
    return ctx.model.simulate(ctx.noise.u)


def noise_prediction(ctx: DiagnosisContext) -> np.ndarray:
    """The model's prediction of the whole noise recording's ear signal (FS): the shared value
    ``noise-prediction``."""
    return ctx.value("noise-prediction")


def linear_part(model: Model) -> Model:
    """The model without its input polynomial and disturbance (delay and LTI core only)."""
    return Model(path=model.path, fs=model.fs, A=model.A, B=model.B, C=model.C, D=model.D, delay=model.delay)
