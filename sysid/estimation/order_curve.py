"""The order/error/cost trade-off of one session: what each model order reaches, and what it costs on the board.

An ANC engineer chooses a secondary-path model on this curve. For each order n it holds:

- the validation rms on the sweeps (FS) of the frequency-limited balanced truncation of the
  session's least-squares FIR to n states (``sysid.estimation.long_response``), on the sweeps'
  spectra (``sysid.validation.sweeps.CompressedValidation``: cells of ``LADDER_CELL_HZ``); a
  model refined at that order (output error) reaches as low or lower;
- the frequency-limited Hankel singular values of the FIR: sigma_(n+1) over sigma_1 says how
  much of the response in band any model of n states leaves out (Gawronski & Juang 1990; twice
  the sum of the values left out bounds the truncation's error in band);
- the board cost of its second-order sections (``sysid.core.board``).

``ladder`` walks the orders upwards on a geometric grid until the rms has stopped falling
(``LADDER_PATIENCE`` steps without ``LADDER_GAIN``), then finds by bisection the lowest order
whose rms is within ``min_gain`` of the best (or within ``at_floor`` times the noise floor):
the lowest order at the floor the data allow. The models the pipeline refined are added to the
curve as they come (``OrderCurve.refined``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.board import board_cost
from ..core.thresholds import (LADDER_CELL_HZ, LADDER_CELLS, LADDER_GAIN, LADDER_NEAR, LADDER_PATIENCE,
                               LADDER_RESOLUTION, LADDER_STEP, MIN_GAIN, ORDER_AT_FLOOR)
from ..validation.sweeps import CompressedValidation, SweepSpectrum
from .long_response import FrequencyLimitedTruncation

__all__ = ["OrderCurve", "ladder", "ladder_grid"]


@dataclass
class OrderCurve:
    """Validation rms (FS) of the truncation ladder's orders, the noise floor (FS), the Hankel singular values of
    the estimate the ladder truncates, and the refined models' (order -> rms, FS)."""

    orders: list[int]
    rms: list[float]
    noise_floor: float
    hankel_singular_values: np.ndarray
    source: str
    refined: dict[int, float] = field(default_factory=dict)
    chosen: int | None = None

    def ratio(self, n: int) -> float:
        """The ladder's rms at order n over the noise floor (n must be on the ladder)."""
        return self.rms[self.orders.index(n)] / self.noise_floor

    def lowest_at_floor(self, at_floor: float = ORDER_AT_FLOOR, min_gain: float = MIN_GAIN,
                        cap: int | None = None) -> int:
        """The lowest ladder order within ``min_gain`` of the best rms, or within ``at_floor`` times the floor;
        among orders up to ``cap`` when given."""
        pairs = [(n, r) for n, r in zip(self.orders, self.rms) if cap is None or n <= cap]
        if not pairs:
            return 0
        best = min(r for _, r in pairs)
        limit = max(best * (1 + min_gain), at_floor * self.noise_floor)
        return min(n for n, r in pairs if r <= limit)

    def best_ratio(self) -> float:
        return min(self.rms) / self.noise_floor

    def to_dict(self) -> dict:
        """The curve as the model's provenance stores it (``sysid.core.model``, ``identification["order_curve"]``)."""
        shown = max(self.orders) if self.orders else 0
        hsv = self.hankel_singular_values[: shown + 1]
        relative = hsv / hsv[0] if hsv.size and hsv[0] > 0 else hsv
        costs = [board_cost(n) for n in self.orders]
        refined = sorted(self.refined.items())
        return {
            "source": self.source,
            "noise_floor": self.noise_floor,
            "orders": [int(n) for n in self.orders],
            "rms": [float(r) for r in self.rms],
            "ratio": [round(float(r) / self.noise_floor, 4) for r in self.rms],
            "hankel_singular_values": [float(h) for h in relative],
            "sections": [c.sections for c in costs],
            "q15_block": [round(c.block, 1) for c in costs],
            "q15_step": [round(c.step, 1) for c in costs],
            "refined_orders": [int(n) for n, _ in refined],
            "refined_rms": [float(r) for _, r in refined],
            "refined_ratio": [round(float(r) / self.noise_floor, 4) for _, r in refined],
            "chosen": None if self.chosen is None else int(self.chosen),
        }


def ladder_grid(max_order: int, step: float = LADDER_STEP) -> list[int]:
    """Every order up to 12, then orders a factor ``step`` apart, up to ``max_order``."""
    orders = set(range(1, min(12, max_order) + 1))
    n = 12.0
    while n < max_order:
        n *= step
        orders.add(min(int(round(n)), max_order))
    return sorted(orders)


def ladder(truncation: FrequencyLimitedTruncation, sweeps: list[SweepSpectrum], floor: float,
           at_floor: float = ORDER_AT_FLOOR, min_gain: float = MIN_GAIN, patience: int = LADDER_PATIENCE,
           max_order: int | None = None) -> OrderCurve:
    """The validation rms of ``truncation``'s orders on the sweeps (module docstring), up to ``max_order``.

    The cells of the compressed validation are at most ``LADDER_CELL_HZ`` wide and at most 1 / LADDER_CELLS of the
    FIR's resolution fs / length: a response tens of milliseconds long turns its phase within a few hertz, and its
    error far below the response (the HD 600: 1e-5 of its peak) is the floor's size (2 Hz cells read the FIR of
    the HD 600 at 1.16x where its exact validation rms is 1.07x).
    """
    cell = min(LADDER_CELL_HZ, truncation.fs / (LADDER_CELLS * truncation.taps.size))
    validation = CompressedValidation(sweeps, cell)
    z = np.exp(2j * np.pi * validation.frequencies / validation.fs)
    top = truncation.max_order if max_order is None else min(max_order, truncation.max_order)
    measured: dict[int, float] = {}

    def rms(n: int) -> float:
        if n not in measured:
            measured[n] = float(validation.rms(truncation.response(n, z))[0])
        return measured[n]

    best, since = np.inf, 0
    for n in ladder_grid(top):
        value = rms(n)
        if value < best * (1 - LADDER_GAIN):
            since = 0
        else:
            since += 1
        best = min(best, value)
        if since >= patience and best <= LADDER_NEAR * floor:
            break
    # Bisection between the ladder's first order within the limit and the one below it.
    limit = max(best * (1 + min_gain), at_floor * floor)
    grid = sorted(measured)
    first = next(n for n in grid if measured[n] <= limit)
    below = max((n for n in grid if n < first), default=0)
    # To within LADDER_RESOLUTION of the order: a state more or less among hundreds is below what the sweeps tell.
    while first - below > max(1, int(LADDER_RESOLUTION * first)):
        middle = (first + below) // 2
        if rms(middle) <= limit:
            first = middle
        else:
            below = middle
    orders = sorted(measured)
    return OrderCurve(orders, [measured[n] for n in orders], floor, truncation.hankel_singular_values,
                      "frequency-limited balanced truncation of the least-squares FIR")
