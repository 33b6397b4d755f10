"""Second-order sections of a realisation: pairing, ordering, relative degree, scaling.

Each section is H_k(z) = (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2) with
one or two poles. A section holding p poles and q <= p finite zeros has the
numerator z^-(p-q) prod_i (1 - z_i z^-1): the missing zeros sit at infinity, so
the relative degree (the delay of a strictly proper model) is preserved. Padding
zeros at the origin instead, as scipy's ``zpk2sos`` does, would advance the
output by one sample per missing zero.

Pairing and ordering follow the rules of the design reference: each pole set
(a complex pair, or two real poles) takes the zeros nearest to it, the sets
closest to the unit circle are served first, and they are placed last in the
cascade. Scaling makes the peak gain from the cascade input to the output of each
section but the last equal to the headroom (L-infinity norm by default, or the
L1 norm of the impulse response, which rules out overflow for any input).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.signal

from sysid import lti

from .errors import CodegenError
from .realise import Realisation

__all__ = ["Cascade", "Section", "cascade_response", "design_cascade", "impulse_l1", "pair_sections", "peak_grid", "scale_sections"]

SCALINGS = ("linf", "l1")


@dataclass(frozen=True)
class Section:
    """One section: numerator b (3 taps in z^-1), denominator a = (1, a1, a2), its poles."""

    b: tuple[float, float, float]
    a: tuple[float, float, float]
    poles: tuple[complex, ...]
    zeros: tuple[complex, ...]

    @property
    def order(self) -> int:
        """Number of poles (0, 1 or 2); fixes the recursion y = w + base(y1, y2)."""
        return len(self.poles)

    @property
    def radius(self) -> float:
        return max((abs(p) for p in self.poles), default=0.0)

    def response(self, w: np.ndarray) -> np.ndarray:
        """H_k(e^{j w}) at normalised angular frequencies w (rad/sample)."""
        zi = np.exp(-1j * np.asarray(w))
        return (self.b[0] + self.b[1] * zi + self.b[2] * zi**2) / (self.a[0] + self.a[1] * zi + self.a[2] * zi**2)


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


def _split_conjugates(values: np.ndarray, tol: float = 1e-9):
    """Real values and upper-half-plane representatives of conjugate pairs."""
    values = np.asarray(values, dtype=complex)
    scale = np.maximum(1.0, np.abs(values))
    real = np.sort(values[np.abs(values.imag) <= tol * scale].real)[::-1]
    upper = values[values.imag > tol * scale]
    return [float(r) for r in real], [complex(u) for u in upper]


def pair_sections(poles, zeros) -> list[tuple[tuple[complex, ...], tuple[complex, ...]]]:
    """Group poles into sets of at most two and give each the nearest zeros.

    Returns [(poles, zeros)] ordered from the set farthest from the unit circle
    to the closest. Complex zero pairs always stay together, and a pair is only
    given to a two-pole set while enough two-pole sets remain for the others.
    """
    real_p, upper_p = _split_conjugates(poles)
    real_z, upper_z = _split_conjugates(zeros)
    if len(real_z) + 2 * len(upper_z) > len(real_p) + 2 * len(upper_p):
        raise CodegenError("model has more finite zeros than poles; it is not proper")
    sets: list[tuple[complex, ...]] = [(p, p.conjugate()) for p in upper_p]
    # Real poles pair up from the circle inwards (scipy zpk2sos does the same).
    real_p.sort(key=lambda p: -abs(p))
    for i in range(0, len(real_p) - 1, 2):
        sets.append((complex(real_p[i]), complex(real_p[i + 1])))
    if len(real_p) % 2:
        sets.append((complex(real_p[-1]),))
    # Serve the pole sets closest to the circle first: their zeros matter most.
    sets.sort(key=lambda s: -max(abs(p) for p in s))
    paired = []
    for index, pole_set in enumerate(sets):
        anchor = max(pole_set, key=lambda p: p.imag)
        capacity = len(pole_set)
        later_pairs = sum(1 for s in sets[index + 1:] if len(s) == 2)
        chosen: list[complex] = []
        best_pair = min(upper_z, key=lambda z: abs(z - anchor), default=None)
        nearest_real = sorted(real_z, key=lambda z: abs(z - anchor))
        take_pair = False
        if capacity == 2 and best_pair is not None:
            must = len(upper_z) > later_pairs
            closer = not nearest_real or abs(best_pair - anchor) <= abs(nearest_real[0] - anchor)
            take_pair = must or closer
        if take_pair:
            upper_z.remove(best_pair)
            chosen = [best_pair, best_pair.conjugate()]
        else:
            # Real zeros fill the capacity; complex pairs still owed have their two-pole sets
            # reserved by the `must` rule above.
            for z in nearest_real[:capacity]:
                real_z.remove(z)
                chosen.append(complex(z))
        paired.append((pole_set, tuple(chosen)))
    if real_z or upper_z:
        raise CodegenError("could not pair all zeros with poles")
    return paired[::-1]


def _section(poles, zeros, gain: float = 1.0) -> Section:
    """Section with the given poles/zeros; missing zeros are placed at infinity."""
    a = np.real(np.poly(poles)) if poles else np.array([1.0])
    num = np.real(np.poly(zeros)) if zeros else np.array([1.0])
    # z^-(p - q) prod(1 - z_i z^-1): shift the numerator right by the deficit.
    num = np.concatenate((np.zeros(len(poles) - len(zeros)), num)) * gain
    b = np.zeros(3)
    b[: num.size] = num
    a3 = np.zeros(3)
    a3[: a.size] = a
    return Section(b=tuple(float(v) for v in b), a=tuple(float(v) for v in a3),
                   poles=tuple(complex(p) for p in poles), zeros=tuple(complex(z) for z in zeros))


def peak_grid(poles, points: int = 4096) -> np.ndarray:
    """Angular frequencies (rad/sample) dense enough to find the peak of |H|.

    A uniform grid misses the peak of a pole at radius r, whose -3 dB width is
    about 2(1 - r) rad; points are added within a few widths of each pole angle.
    """
    grid = [np.linspace(0.0, np.pi, points)]
    for p in np.asarray(poles, dtype=complex):
        width = max(1.0 - abs(p), 1e-7)
        theta = abs(np.angle(p))
        grid.append(np.clip(theta + width * np.linspace(-8, 8, 161), 0.0, np.pi))
    return np.unique(np.concatenate(grid))


def cascade_response(sections, w: np.ndarray, upto: int | None = None) -> np.ndarray:
    """Product of the section responses (first ``upto`` sections) at frequencies w."""
    response = np.ones(np.shape(w), dtype=complex)
    for section in list(sections)[:upto]:
        response = response * section.response(w)
    return response


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


def design_cascade(realisation: Realisation, scaling: str = "linf", headroom_db: float = 6.0) -> Cascade:
    """Sections of the realised LTI core, ordered, with the model's gain and scaled.

    The overall gain is the least-squares fit of the unit-gain cascade to the
    state-space frequency response on the peak grid; the remaining relative error
    is reported (it is round-off, about 1e-12, unless the zeros are ill-conditioned).
    """
    A, B, C, D = realisation.A, realisation.B, realisation.C, realisation.D
    if A.shape[0] == 0:
        unit = [_section((), ())]
        poles = np.zeros(0)
    else:
        poles = np.linalg.eigvals(A)
        zeros = lti.invariant_zeros(A, B, C, D)
        unit = [_section(p, z) for p, z in pair_sections(poles, zeros)]
    w = peak_grid(poles)
    target = lti.frequency_response(A, B, C, D, np.exp(1j * w))
    shape = cascade_response(unit, w)
    total = float(np.real(np.vdot(shape, target) / np.vdot(shape, shape))) if np.any(shape) else 0.0
    if total == 0.0:
        raise CodegenError("model has zero gain; there is nothing to generate")
    scaled, gains = scale_sections(unit, total, scaling, headroom_db)
    error = float(np.max(np.abs(cascade_response(scaled, w) - target)) / np.max(np.abs(target)))
    return Cascade(sections=tuple(scaled), scaling=scaling, headroom_db=float(headroom_db),
                   node_gains=tuple(float(g) for g in gains), realisation_error=error)
