"""Sessions with hidden effects and the nominal-order models that miss them, shared by the tests.

The model under diagnosis is what a user gets at the seed's published order
(FB n = 7, FF n = 5) on a coarse grid: fast, and blind to the hidden effect.
"""

from __future__ import annotations

from functools import lru_cache

from sysid.identify import IdentificationOptions, identify
from sysid.simulate import simulate_session

from conftest import short_spec

NOMINAL_ORDER = {"fb": 7, "ff": 5}
# Refits in tests: a few gammas instead of the step-30 grid keep each refit to seconds.
TEST_REFIT = IdentificationOptions(gammas=(50, 100, 200, 400), refine_seconds=3.0)


def nominal_options(path: str) -> IdentificationOptions:
    return IdentificationOptions(gammas=(100, 300, 500), orders=(NOMINAL_ORDER[path],), refine_seconds=2.0)


@lru_cache(maxsize=None)
def effect_case(path: str, seed: int, effects: tuple[str, ...]):
    """(session, model at the nominal order) for a short session with the given effects."""
    session = simulate_session(short_spec(path, seed), effects=list(effects))
    model = identify(session.noise, session.sweeps, path, nominal_options(path)).model
    return session, model
