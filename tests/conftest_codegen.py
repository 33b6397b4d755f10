"""Shared helpers of the codegen and firmware tests: plants, sweeps, tool checks.

Imported explicitly by the test modules (``from conftest_codegen import ...``);
sweeps are synthesised here so the tests need no recordings.
"""

from __future__ import annotations

import shutil

import numpy as np
import scipy.signal

from sysid.model import Model
from sysid.plants import appendix_a_model

__all__ = ["FS", "appendix_a_model", "have", "log_sweep", "model_sweeps", "random_stable_model"]

FS = 44100.0


def log_sweep(seconds: float = 0.25, fs: float = FS, f0: float = 20.0, f1: float = 4000.0) -> np.ndarray:
    """Unit-amplitude exponential sweep f0 -> f1 Hz."""
    t = np.arange(int(seconds * fs)) / fs
    return scipy.signal.chirp(t, f0, t[-1], f1, method="logarithmic")


def model_sweeps(model: Model, seconds: float = 0.25, peak: float = 0.5) -> list[np.ndarray]:
    """Two validation-like sweeps (exponential, then linear) scaled so the model output peaks at ``peak``."""
    sweeps = []
    for method in ("logarithmic", "linear"):
        t = np.arange(int(seconds * model.fs)) / model.fs
        s = scipy.signal.chirp(t, 20.0, t[-1], 4000.0, method=method)
        s *= min(1.0, peak / np.max(np.abs(model.simulate(s))))
        sweeps.append(s)
    return sweeps


def random_stable_model(seed: int, order: int, path: str = "fb", delay: int = 0, radius_max: float = 0.999,
                        strictly_proper: bool = True) -> Model:
    """Random real model with poles in a ring close to the unit circle (seeded)."""
    rng = np.random.default_rng(seed)
    poles = []
    while len(poles) < order:
        r = rng.uniform(0.9, radius_max)
        if order - len(poles) >= 2 and rng.random() < 0.7:
            theta = rng.uniform(0.005, 0.6)
            poles += [r * np.exp(1j * theta), r * np.exp(-1j * theta)]
        else:
            poles.append(r)
    from sysid.lti import real_block_diagonal

    A = real_block_diagonal(np.array(poles))
    B = rng.standard_normal((order, 1))
    C = rng.standard_normal((1, order))
    D = np.zeros((1, 1)) if strictly_proper else rng.standard_normal((1, 1))
    return Model(path=path, fs=FS, A=A, B=B, C=C, D=D, delay=delay)


def have(tool: str) -> bool:
    return shutil.which(tool) is not None
