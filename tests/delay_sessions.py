"""Random helmets' noise recordings behind a delay read short or long, shared by the delay tests."""

from __future__ import annotations

import numpy as np

from sysid.core import lti
from sysid.estimation.delay import compensate_delay
from sysid.random_plant import random_plant, random_session

BAND = (20.0, 5000.0)


def behind_delay(seed: int, off_by: int):
    """(random plant ``seed``, its 2 s noise body with rp.delay + off_by samples taken out: short when
    off_by < 0, long when > 0)."""
    rp = random_plant(seed)
    session = random_session(seed, noise_duration=5.0, sweep_duration=0.5)
    return rp, compensate_delay(session.noise.trimmed(3.0), rp.delay + off_by)


def with_spare_poles(rp, spare) -> np.ndarray:
    """A = the plant's poles and the spare ones, real block diagonal."""
    return lti.real_block_diagonal(np.concatenate([np.linalg.eigvals(rp.model.A), spare]))
