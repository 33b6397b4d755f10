"""Scaling of a realisation's second-order sections for the fixed- and floating-point filters.

The sections themselves (pairing, ordering, relative degree) come from
``sysid.core.sections``; ``design_cascade`` takes another order of them when the plan
(``codegen.plan``) moves the sections whose round-off dominates. Scaling makes the peak
gain from the cascade input to the output of each section but the last equal to the
headroom (L-infinity norm by default, or the L1 norm of the impulse response, which rules
out overflow for any input).
Below the steps of firmware generation: a design module the plan runs after
:mod:`codegen.realise`, the only module of ``codegen`` it imports besides the errors.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.signal

from sysid.core import lti
from sysid.core.errors import ModelError
from sysid.core.sections import Section, cascade_response, pair_sections, peak_grid, unit_section

from .errors import CodegenError
from .realise import Realisation

__all__ = ["Cascade", "Section", "cascade_response", "design_cascade", "impulse_l1", "pair_sections", "peak_grid", "scale_sections"]

SCALINGS = ("linf", "l1")


@dataclass(frozen=True)
class Cascade:
    """Scaled sections in processing order and the figures of their design.

    ``node_gains[k]`` is the peak gain (in the chosen norm) from the cascade input
    to the output of section k; ``realisation_error`` is the relative peak error
    max|H_sos - H| / max|H| of the cascade against the realised state space.
    """

    sections: tuple[Section, ...]
    scaling: str
    headroom_db: float
    node_gains: tuple[float, ...]
    realisation_error: float
    # The sections' order as positions in the paired order (``pair_sections``, farthest from the unit circle
    # first); the identity unless the plan moved a section whose round-off dominated (``codegen.plan``).
    order: tuple[int, ...] = ()


def impulse_l1(sections, poles) -> float:
    """Sum |h(t)| of the cascade, simulated until the slowest mode has decayed to 1e-9."""
    radius = min(max((abs(p) for p in poles), default=0.0), 1 - 1e-7)
    length = int(min(max(64, np.log(1e-9) / np.log(radius) if radius > 0 else 64), 4_000_000))
    impulse = np.zeros(length)
    impulse[0] = 1.0
    sos = np.array([list(s.b) + list(s.a) for s in sections])
    return float(np.sum(np.abs(scipy.signal.sosfilt(sos, impulse))))


def scale_sections(sections, total_gain: float, scaling: str = "linf", headroom_db: float = 6.0):
    """Scale unit-gain sections so partial cascades peak at the headroom level.

    Section k (k < K) gets the gain g_k making the norm of H_1...H_k equal to
    10^(-headroom/20); the last section takes what remains so that the cascade
    equals total_gain * prod H_k. Returns (sections, node_gains).
    """
    if scaling not in SCALINGS:
        raise CodegenError(f"scaling must be one of {', '.join(SCALINGS)}; found {scaling!r}")
    if headroom_db < 0:
        raise CodegenError(f"headroom must be non-negative dB; found {headroom_db}")
    target = 10 ** (-headroom_db / 20)
    poles = [p for s in sections for p in s.poles]
    w = peak_grid(poles)
    scaled: list[Section] = []
    applied = 1.0
    gains = []
    for k, section in enumerate(sections):
        trial = scaled + [section]
        if scaling == "linf":
            norm = float(np.max(np.abs(cascade_response(trial, w))))
        else:
            norm = impulse_l1(trial, [p for s in trial for p in s.poles])
        if k < len(sections) - 1:
            g = target / norm if norm > 0 else 1.0
        else:
            g = total_gain / applied
        applied *= g
        scaled.append(replace(section, b=tuple(float(v) * g for v in section.b)))
        gains.append(abs(norm * g))
    return scaled, gains


def design_cascade(realisation: Realisation, scaling: str = "linf", headroom_db: float = 6.0,
                   order=None) -> Cascade:
    """Sections of the realised LTI core, ordered, with the model's gain and scaled.

    ``order``: the sections as positions in ``pair_sections``'s order (None: that order). The overall gain is
    the least-squares fit of the unit-gain cascade to the state-space frequency response on the peak grid; the
    remaining relative error is reported (it is round-off, about 1e-12, unless the zeros are ill-conditioned).
    """
    A, B, C, D = realisation.A, realisation.B, realisation.C, realisation.D
    if A.shape[0] == 0:
        unit = [unit_section((), ())]
        poles = np.zeros(0)
    else:
        poles = np.linalg.eigvals(A)
        zeros = lti.invariant_zeros(A, B, C, D)
        try:
            unit = [unit_section(p, z) for p, z in pair_sections(poles, zeros)]
        except ModelError as exc:
            raise CodegenError(str(exc)) from None
    order = tuple(range(len(unit))) if order is None else tuple(int(k) for k in order)
    if sorted(order) != list(range(len(unit))):
        raise CodegenError(f"section order must be a permutation of 0..{len(unit) - 1}; found {list(order)}")
    unit = [unit[k] for k in order]
    w = peak_grid(poles)
    target = lti.frequency_response(A, B, C, D, np.exp(1j * w))
    shape = cascade_response(unit, w)
    total = float(np.real(np.vdot(shape, target) / np.vdot(shape, shape))) if np.any(shape) else 0.0
    if total == 0.0:
        raise CodegenError("model has zero gain; there is nothing to generate")
    scaled, gains = scale_sections(unit, total, scaling, headroom_db)
    error = float(np.max(np.abs(cascade_response(scaled, w) - target)) / np.max(np.abs(target)))
    return Cascade(sections=tuple(scaled), scaling=scaling, headroom_db=float(headroom_db),
                   node_gains=tuple(float(g) for g in gains), realisation_error=error, order=order)
