"""Random helmets' noise recordings behind a delay read short or long, shared by the delay tests."""

from __future__ import annotations

import numpy as np

from sysid.core import lti
from sysid.core.model import Model
from sysid.estimation.delay import compensate_delay
from sysid.estimation.output_error import block_data, refine_output_error
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


def core_read_long(rp, session, by: int, transient_s: float):
    """Random helmet ``rp``'s poles and a spare one at z = -1 fitted behind a delay ``by`` samples long (what a core
    does with a lead it cannot have), as a model of that delay."""
    long = rp.delay + by
    body = compensate_delay(session.noise.trimmed(transient_s), long)
    A = lti.real_block_diagonal(np.concatenate([np.linalg.eigvals(rp.model.A), [-0.99999]]))
    n = A.shape[0]
    fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)),
                              block_data(body, max_seconds=1.0), max_iterations=20)
    return Model(path="fb", fs=rp.fs, A=fit.A, B=fit.B, C=fit.C, D=fit.D, delay=long)
