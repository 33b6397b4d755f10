"""The modal parametrisation of output-error refinement: poles as parameters, the modal basis, the decay bound.

With A in real block-diagonal (modal) form, a 2x2 block [[a, b], [-b, a]] per pole pair
a +- jb and a 1x1 block per real pole, and C = [1 0 | 1 0 | 1 ...], the transfer function's
columns C (zI - A)^-1 e_j are known in closed form per block (``modal_basis``) and
everything but the poles enters the model linearly. The poles are parametrised so that
every iterate is stable and no slower than the block can resolve: a complex pair as
r e^{+-j theta} with r = exp(-exp(sigma) - m), a real pole as exp(-m) tanh(xi), where the
margin m is the block's ``decay_bound`` 1/L (``poles_to_params``, ``params_to_poles``,
``pole_derivatives``). Poles the block could not hold run out to that bound
(``radius_bound_mask``); a pair run to the real axis is refined as two real poles
(``split_near_real_pairs``). The thresholds of these decisions are
``sysid.core.thresholds``' ``AT_RADIUS_BOUND``, ``NEAR_REAL_PAIR`` and ``NEAR_REAL_SPLIT``.
"""

from __future__ import annotations

import numpy as np

from ..core.thresholds import AT_RADIUS_BOUND, NEAR_REAL_PAIR, NEAR_REAL_SPLIT
from .output_error_data import BlockData

__all__ = ["modal_basis", "decay_bound", "radius_bound_mask", "at_radius_bound", "split_near_real_pairs",
           "poles_to_params", "params_to_poles", "pole_derivatives"]

# Decay bound without a block: stability alone (|p| <= 1 - 1e-9).
_STABLE = 1e-9


def modal_basis(A_block: np.ndarray, C: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Columns C (zI - A)^-1 e_j for a real block-diagonal A (M x n), in closed form per block.

    Column-major, each column written contiguously."""
    n = A_block.shape[0]
    basis = np.empty((z.size, n), dtype=complex, order="F")
    i = 0
    while i < n:
        if i + 1 < n and A_block[i, i + 1] != 0:
            a, b = A_block[i, i], A_block[i, i + 1]
            # (zI - [[a, b], [-b, a]])^-1 = [[z - a, b], [-b, z - a]] / ((z - a)^2 + b^2)
            # Each quotient written straight into its column, the numerators into one scratch array
            # (the same operations and operand order as the plain expressions: the same bits).
            shifted = z - a
            den = np.square(shifted)
            den += b**2
            c0, c1 = C[0, i], C[0, i + 1]
            numerator = np.multiply(c0, shifted)
            numerator -= c1 * b
            np.divide(numerator, den, out=basis[:, i])
            np.multiply(c1, shifted, out=numerator)
            np.add(c0 * b, numerator, out=numerator)
            np.divide(numerator, den, out=basis[:, i + 1])
            i += 2
        else:
            shifted = z - A_block[i, i]
            np.divide(C[0, i], shifted, out=basis[:, i])
            i += 1
    return basis


def decay_bound(data: BlockData) -> float:
    """Smallest decay rate -ln|p| (per sample) of a pole refined on the block: 1/L, L its length.

    A pole whose time constant -1/ln|p| is longer than the block's L samples cannot be told
    from the block's transient term (the x_delta columns): the data do not resolve it. Before
    this bound (|p| <= 1 - 1e-9) spare poles ran to z = 1 or z = -1 out of the fitted band,
    invisible in the sweeps' spectra but ringing in the simulated sweeps (random helmet 41, short
    session: a pair at 23944 Hz and a real pole at z = -1 with large residues cancelling in band,
    70000x the floor in simulation) and in a controller built on the model. Lightly damped
    in-band modes stay reachable: Q 50 at 30 Hz and 48 kHz is 1 - |p| = pi 30 / (50 48000) =
    3.9e-5, above 1/L = 2.1e-5 for a 1 s block (2.1e-6 for 10 s). A tighter bound out of the band
    (the decay of a Q 50 mode at the pole's distance from it) put two random helmets above the floor
    (thesis-length 13: 1.21x, short 1: 1.41x, both at the floor with 1/L alone) and is not used.
    """
    return 1.0 / data.length


def radius_bound_mask(poles: np.ndarray, data: BlockData) -> np.ndarray:
    """Which of ``poles`` sit at the block's ``decay_bound`` (decay -ln|p| within 1 % of it): poles
    the block could not hold, run out to the limit of the parametrisation."""
    decay = -np.log(np.maximum(np.abs(np.asarray(poles)), 1e-300))
    return decay <= (1 + AT_RADIUS_BOUND) * decay_bound(data)


def at_radius_bound(poles: np.ndarray, data: BlockData) -> bool:
    """Whether any of ``poles`` sits at the block's ``decay_bound`` (``radius_bound_mask``)."""
    return bool(np.any(radius_bound_mask(poles, data)))


def poles_to_params(poles: np.ndarray, margin: float = _STABLE) -> tuple[np.ndarray, int]:
    """Parameter vector (sigma, theta per upper-half-plane pair, then xi per real pole) under the
    decay bound ``margin`` (-ln of the largest radius; ``decay_bound``); poles beyond it start inside it."""
    pairs = [p for p in poles if p.imag > 1e-12]
    reals = [p.real for p in poles if abs(p.imag) <= 1e-12]
    params = []
    for p in pairs:
        r = min(abs(p), 1 - 1e-12)
        # A start at or beyond the bound begins a tenth of the bound's decay inside it, where sigma still moves it.
        params += [np.log(max(-np.log(r) - margin, 0.1 * margin)), np.angle(p)]
    params += [np.arctanh(np.clip(p / np.exp(-margin), -1 + 1e-12, 1 - 1e-12)) for p in reals]
    return np.array(params, dtype=float), len(pairs)


def split_near_real_pairs(poles: np.ndarray, margin: float = _STABLE) -> np.ndarray:
    """The poles with every nearly real pair replaced by two real poles of nearby decay rates.

    A pair r e^{+-j theta} whose angle theta is below NEAR_REAL_PAIR times its decay rate d = -ln r is a
    double real pole in all but name; the cost is even in theta there, so its theta column of the
    Jacobian vanishes (2.3e-7 of the largest on random helmet 17's final 10 s block, theta = 1.1e-7,
    d = 0.015), the scaled Gauss-Newton step along it is unbounded (12 rad), and the trust region
    crawls: 44 evaluations for 0.42 % of the cost. The parametrisation holds a pair in the upper half
    plane, so a pair the data want as two distinct real poles (two roll-off corners) runs to theta = 0
    and stays there. The two real poles have decay rates (1 +- NEAR_REAL_SPLIT) d (inside the decay
    bound ``margin`` when the pair is): the response moves by O(NEAR_REAL_SPLIT^2), and from there
    the same block took 16 evaluations to a lower cost (1016 noise variances sigma^2 below the start,
    against 420). ``identify`` asks for it
    in the final refinement only: every refit of the order search and the delay steps split too sends
    their chains elsewhere (random helmet 6, thesis length: n 16 and 6.4 s of CPU against n 14, 4.5 s).
    """
    poles = np.asarray(poles, dtype=complex)
    decay = -np.log(np.maximum(np.abs(poles), 1e-300))
    near = (poles.imag > 1e-12) & (np.abs(np.angle(poles)) < NEAR_REAL_PAIR * decay)
    if not np.any(near):
        return poles
    keep = np.ones(poles.size, dtype=bool)
    split = []
    for p, d in zip(poles[near], decay[near]):
        keep &= np.abs(poles - np.conj(p)) > 1e-15
        faster = np.exp(-(1 + NEAR_REAL_SPLIT) * d)
        slower = np.exp(-max((1 - NEAR_REAL_SPLIT) * d, margin))
        split += [faster, slower]
    keep &= ~near
    return np.concatenate([poles[keep], np.array(split, dtype=complex)])


def params_to_poles(params: np.ndarray, pairs: int, margin: float = _STABLE) -> np.ndarray:
    """The poles of a parameter vector (``poles_to_params`` inverted): the ``pairs`` upper poles, their
    conjugates, then the real poles, all within the decay bound ``margin``."""
    sigma, theta = params[0:2 * pairs:2], params[1:2 * pairs:2]
    # The margin keeps |p| below 1, and within what the block resolves, however far sigma or xi run.
    r = np.exp(-np.exp(np.minimum(sigma, 700.0)) - margin)
    upper = r * np.exp(1j * theta)
    return np.concatenate([upper, np.conj(upper), (np.exp(-margin) * np.tanh(params[2 * pairs:])).astype(complex)])


def pole_derivatives(params: np.ndarray, pairs: int, margin: float) -> np.ndarray:
    """d pole / d parameter, one per parameter: -e^sigma p and j p for a pair's (sigma, theta)
    (upper pole), exp(-margin) (1 - tanh^2 xi) for a real pole's xi."""
    upper = params_to_poles(params, pairs, margin)[:pairs]
    out = np.empty(params.size, dtype=complex)
    out[0:2 * pairs:2] = -np.exp(np.minimum(params[0:2 * pairs:2], 700.0)) * upper
    out[1:2 * pairs:2] = 1j * upper
    out[2 * pairs:] = np.exp(-margin) * (1 - np.tanh(params[2 * pairs:]) ** 2)
    return out


def _block_basis(pole: complex, z: np.ndarray) -> np.ndarray:
    """``modal_basis`` columns of one block: a pair a +- jb with C = [1, 0], or a real pole with C = [1]."""
    if pole.imag == 0:
        return (1.0 / (z - pole.real))[:, None]
    a, b = pole.real, pole.imag
    den = (z - a) ** 2 + b**2
    return np.stack([(z - a) / den, b / den], axis=1)
