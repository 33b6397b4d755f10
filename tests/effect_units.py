"""A detector's context on a session whose model is the true plant without the hidden effect.

The detectors' unit tests need no identification: the model is exactly right but for
the effect under test, so what the detector must find is known analytically.
"""

from __future__ import annotations

from functools import lru_cache

from conftest import short_spec

from sysid.core.model import Model
from sysid.findings import DiagnosisContext
from sysid.simulate import simulate_session
from sysid.validation.compare import compare


@lru_cache(maxsize=None)
def true_session(path: str, seed: int, effects: tuple[str, ...]):
    return simulate_session(short_spec(path, seed), effects=list(effects))


def true_context(path: str, seed: int, effects: tuple[str, ...]) -> DiagnosisContext:
    """The context of the true base plant on a short session with the effects (a new one each call:
    a context belongs to one diagnosis)."""
    session = true_session(path, seed, effects)
    model = Model.from_dict(session.truth.get("base_plant", session.truth["plant"]))
    return DiagnosisContext(model, session.noise, session.sweeps, compare(model, session.sweeps))
