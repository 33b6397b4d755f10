"""One helmet on many heads: true plants that differ as riders do, for simulated batches.

The same helmet on another head keeps its modes but not exactly: head size and ear-cup
seal shift the mode frequencies by a few percent and change their damping, and the
leak past the seal moves the plant's real (non-oscillating) poles, which shape its
lowest frequencies (the high-pass of a leaky cavity). ``rider_variant`` applies that to
a plant in modal form G(z) = D + sum_i r_i / (z - p_i): each pole is mapped to continuous
time, s_i = fs ln p_i = -sigma_i + j omega_i, and moved to
s_i' = -sigma_i (1 + delta_sigma) + j omega_i (1 + delta_omega), one draw per conjugate
pair, delta_sigma drawn with the damping spread for a mode and the leak spread for a
real pole; residues are kept. The order stays the plant's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sysid.core import lti
from sysid.core.errors import HelmetAncError
from sysid.core.model import Model
from sysid.estimation.subspace import fit_b_d

__all__ = ["RiderSpread", "rider_variant"]


@dataclass(frozen=True)
class RiderSpread:
    """How much heads differ: relative standard deviations of the mode frequencies, of
    the modes' damping and of the real poles' decay rates (the leak)."""

    frequency: float = 0.02
    damping: float = 0.15
    leak: float = 0.3


def rider_variant(plant: Model, seed: int, spread: RiderSpread = RiderSpread()) -> Model:
    """The plant as heard on another head (see the module docstring); seeded, reproducible."""
    rng = np.random.default_rng(seed)
    modal = lti.modal_form(plant.A, plant.B, plant.C, plant.D)
    if not modal.reliable:
        raise HelmetAncError("plant has no reliable modal form (nearly repeated poles); cannot vary its modes")
    fs = plant.fs
    poles = modal.poles.copy()
    done = np.zeros(poles.size, dtype=bool)
    for i, p in enumerate(poles):
        if done[i]:
            continue
        # One draw per conjugate pair keeps the plant real.
        partner = i
        if abs(p.imag) > 1e-12:
            others = [j for j in range(poles.size) if j != i and not done[j]]
            partner = min(others, key=lambda j: abs(poles[j] - np.conj(p)))
        s = fs * np.log(complex(p))
        real = partner == i
        shift_f = 0.0 if real else rng.normal(0.0, spread.frequency)
        shift_d = rng.normal(0.0, spread.leak if real else spread.damping)
        s_new = complex(s.real * (1.0 + shift_d), s.imag * (1.0 + shift_f))
        poles[i] = np.exp(s_new / fs)
        if partner != i:
            poles[partner] = np.conj(poles[i])
            done[partner] = True
        done[i] = True
    if np.max(np.abs(poles)) >= 1.0:
        raise HelmetAncError("a varied mode left the unit circle; use a smaller damping spread")
    # The varied core in real block-diagonal form, B fitted so the residues are kept.
    A = lti.real_block_diagonal(poles)
    C = lti.block_output_row(A)
    omega = np.linspace(0.001, np.pi * 0.999, 4 * max(64, poles.size))
    z = np.exp(1j * omega)
    target = modal.d + (modal.residues[None, :] / (z[:, None] - poles[None, :])).sum(axis=1)
    B, D = fit_b_d(A, C, omega, target, feedthrough=modal.d != 0.0)
    return Model(path=plant.path, fs=fs, A=A, B=B, C=C, D=D, delay=plant.delay,
                 input_nonlinearity=plant.input_nonlinearity,
                 identification={"source": "rider variant", "seed": seed, "spread": {"frequency": spread.frequency, "damping": spread.damping,
                                                                               "leak": spread.leak}})
