"""Sessions with hidden effects and the nominal-order models that miss them, shared by the tests.

The model under diagnosis is what a user gets at the seed's published order
(FB n = 7, FF n = 5) on a coarse grid without the latency estimate: fast, and blind
to the hidden effect.
``effect_case`` identifies it on the session itself; ``reference_case`` on a clean
session of the same helmet, then re-measured with the effect (a new microphone, a
converter filter, a liner that adds a mode). A series resonance or filter needs the
second: identified on the session itself, a nominal-order model takes the factor in
and gives up a weak mode of the plant instead, so what it misses is not the factor.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from conftest import short_spec

from sysid.identify import IdentificationOptions, identify
from sysid.simulate import simulate_session

NOMINAL_ORDER = {"fb": 7, "ff": 5}
# Refits in tests: a few gammas instead of the step-30 grid keep each refit to seconds.
TEST_REFIT = IdentificationOptions(gammas=(50, 100, 200, 400), refine_seconds=3.0)
# Identification of the every-effect workflow's sessions (tests/test_sysid/effects/test_effects_workflow.py).
WORKFLOW_OPTIONS = IdentificationOptions(gammas=tuple(range(10, 1001, 60)), refine_seconds=3.0)


def nominal_options(path: str) -> IdentificationOptions:
    # Without the latency estimate, as the seed's method: the model is blind to a delay it should miss.
    return IdentificationOptions(gammas=(100, 300, 500), orders=(NOMINAL_ORDER[path],), refine_seconds=2.0,
                                 latency=False)


@lru_cache(maxsize=None)
def effect_case(path: str, seed: int, effects: tuple[str, ...]):
    """(session, model at the nominal order) for a short session with the given effects."""
    session = simulate_session(short_spec(path, seed), effects=list(effects))
    model = identify(session.noise, session.sweeps, path, nominal_options(path)).model
    return session, model


@lru_cache(maxsize=None)
def reference_case(path: str, seed: int, effects: tuple[str, ...]):
    """(session with the effects, model identified on the clean session of the same seed)."""
    return simulate_session(short_spec(path, seed), effects=list(effects)), effect_case(path, seed, ())[1]


def random_factor(kind: str, rng: np.random.Generator) -> tuple[str, dict]:
    """(spec, true parameters) of a series factor with parameters in effects.md's ranges."""
    if kind == "resonance":
        truth = {"f0_hz": float(np.exp(rng.uniform(np.log(60.0), np.log(3600.0)))), "q": float(rng.uniform(3.0, 15.0)),
                 "gain_db": float(rng.uniform(6.0, 14.0) * rng.choice([1, 1, -1]))}
        return f"resonance:{truth['f0_hz']:.1f},{truth['q']:.2f},{truth['gain_db']:.2f}", truth
    if kind == "highpass":
        truth = {"corner_hz": float(rng.uniform(10.0, 80.0)), "order": int(rng.integers(1, 3))}
    else:
        truth = {"corner_hz": float(np.exp(rng.uniform(np.log(1000.0), np.log(16000.0)))), "order": int(rng.integers(1, 3))}
    return f"{kind}:{truth['corner_hz']:.1f},{truth['order']}", truth
