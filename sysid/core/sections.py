"""A model's LTI core as second-order sections: pairing, ordering, relative degree.

Each section is H_k(z) = (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2) with
one or two poles. A section holding p poles and q <= p finite zeros has the
numerator z^-(p-q) prod_i (1 - z_i z^-1): the missing zeros sit at infinity, so
the relative degree (the delay of a strictly proper model) is preserved. Padding
zeros at the origin instead, as scipy's ``zpk2sos`` does, would advance the
output by one sample per missing zero.

Pairing and ordering (design.md, "Firmware generation"): each pole set (a complex
pair, or two real poles) takes the zeros nearest to it, the sets closest to the
unit circle are served first, and they are placed last in the cascade. A
high-order transfer-function polynomial is never formed: rounded to four digits,
the seed's FB polynomial is unstable.

Used by the report (the model's transfer function as a table) and by ``codegen``
(which scales and quantises the sections).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from . import lti
from .errors import ModelError

__all__ = ["Section", "cascade_response", "pair_sections", "peak_grid", "second_order_sections", "sections_response",
           "unit_section"]


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
        raise ModelError("model has more finite zeros than poles; it is not proper")
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
        raise ModelError("could not pair all zeros with poles")
    return paired[::-1]


def unit_section(poles, zeros, gain: float = 1.0) -> Section:
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


def second_order_sections(model) -> list[Section]:
    """Sections of a model's LTI core in processing order, the overall gain in the first.

    The pure ``model.delay`` and any input polynomial are not included. The gain is
    the least-squares fit of the unit-gain cascade to C (zI - A)^-1 B + D on a grid
    that resolves every pole's peak.
    """
    if model.order == 0:
        return [unit_section((), (), float(model.D[0, 0]))]
    poles = model.poles()
    unit = [unit_section(p, z) for p, z in pair_sections(poles, model.zeros())]
    w = peak_grid(poles)
    target = lti.frequency_response(model.A, model.B, model.C, model.D, np.exp(1j * w))
    shape = cascade_response(unit, w)
    gain = float(np.real(np.vdot(shape, target) / np.vdot(shape, shape)))
    unit[0] = replace(unit[0], b=tuple(gain * c for c in unit[0].b))
    return unit


def sections_response(sections, frequencies_hz, fs: float) -> np.ndarray:
    """Product of the sections' responses at frequencies in Hz for sample rate fs in Hz."""
    return cascade_response(sections, 2 * np.pi * np.asarray(frequencies_hz, dtype=float) / fs)
