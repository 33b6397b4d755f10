"""Shared fixtures: short synthetic sessions (seconds of audio) of both appendix-A plants."""

from __future__ import annotations

import numpy as np
import pytest

from sysid.identify import IdentificationOptions, identify
from sysid.simulate import SessionSpec, simulate_session, write_session

# Short sessions keep the suite fast: 8 s of noise (5 s after the transient), 2 s sweeps.
SHORT = dict(noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)
# A coarser gamma grid than the seed's (step 30 instead of 10) keeps the fit below seconds.
FAST_OPTIONS = IdentificationOptions(gammas=tuple(range(10, 1001, 30)))


def short_spec(path: str, seed: int = 0, **changes) -> SessionSpec:
    return SessionSpec(path=path, seed=seed, **{**SHORT, **changes})


@pytest.fixture(scope="session")
def sessions():
    return {path: simulate_session(short_spec(path, seed=11)) for path in ("fb", "ff")}


@pytest.fixture(scope="session")
def identifications(sessions):
    return {path: identify(s.noise, s.sweeps, path, FAST_OPTIONS) for path, s in sessions.items()}


@pytest.fixture(scope="session")
def session_files(sessions, tmp_path_factory):
    """The FF session written as WAV files: {'noise': Path, 'sweep1': Path, 'sweep2': Path, 'truth': Path}."""
    folder = tmp_path_factory.mktemp("ff_session")
    return write_session(sessions["ff"], folder)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)
