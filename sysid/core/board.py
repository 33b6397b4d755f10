"""What a model of n states costs on the ANC board: emulated Cortex-M4 instructions per sample.

The generated filter (``codegen``, design.md "Firmware generation") runs a model as a cascade of
ceil(n / 2) second-order sections, so its cost per sample is a cost per section times their count
plus what each call costs once. The constants are measured, not estimated: instructions executed on
QEMU's ``mps2-an386`` (a Cortex-M4F), counted from its execution trace (``codegen.qemu_cost``) on the
real ELF built with ``arm-none-eabi-gcc -O2``, as BENCHMARKS.md reports them:

- "Firmware generation", "Emulated Cortex-M4: instructions per sample": the Q15 filter (Q31 direct-form-I
  sections with error feedback) processing blocks, 64.0 per sample for the 4 sections of the seed's FB
  model and 48.3 for the 3 of its FF model: 16.0 and 16.1 per section, the Q15 <-> Q31 conversions,
  the delay line and the chunking included (2026-11-23);
- "Board control loop": the per-sample control path calls ``NAME_q15_step`` once a sample, 93
  instructions for a filter of 4 sections and 234 for one of 11 (``ctl_s``, ``ctl_q``): 20.1 per
  section and 12.6 per call (2026-11-23).

These are instructions, not cycles (a load takes 2 cycles on a Cortex-M4, a taken branch 2-4); the
board's budget is 3500 cycles a sample (168 MHz at 48 kHz). ``tests/test_codegen/test_board_cost.py``
checks the constants against a fresh QEMU measurement wherever the cross compiler and QEMU are
installed. ``sysid`` does not import ``codegen``: the figures are kept here, in one place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Q15_BLOCK_PER_SECTION", "Q15_STEP_PER_SECTION", "Q15_STEP_PER_CALL", "BOARD_CYCLES_PER_SAMPLE",
           "BoardCost", "board_cost", "sections"]

# Q15 filter in blocks: instructions per section and sample (BENCHMARKS.md, "Firmware generation").
Q15_BLOCK_PER_SECTION = 16.1
# Q15 one-sample step of the per-sample control path: per section, and per call (BENCHMARKS.md, "Board control loop").
Q15_STEP_PER_SECTION = 20.1
Q15_STEP_PER_CALL = 12.6
# The board's cycles per sample: a 168 MHz Cortex-M4 at 48 kHz.
BOARD_CYCLES_PER_SAMPLE = 3500.0


def sections(order: int) -> int:
    """Second-order sections of a model of ``order`` states (a lone real pole takes a section of its own)."""
    return math.ceil(max(int(order), 0) / 2)


@dataclass(frozen=True)
class BoardCost:
    """Emulated Cortex-M4 instructions per sample of a model's generated Q15 filter: processing blocks
    (``block``) and called once a sample (``step``, the control path's case); ``sections`` of them."""

    order: int
    sections: int
    block: float
    step: float

    @property
    def step_share(self) -> float:
        """The one-sample step's share of the board's cycles per sample (instructions taken as cycles: a lower
        bound)."""
        return self.step / BOARD_CYCLES_PER_SAMPLE

    def to_dict(self) -> dict:
        return {"order": self.order, "sections": self.sections, "q15_block": round(self.block, 1),
                "q15_step": round(self.step, 1)}


def board_cost(order: int) -> BoardCost:
    """The board cost of a model of ``order`` states (module docstring)."""
    count = sections(order)
    return BoardCost(int(order), count, Q15_BLOCK_PER_SECTION * count,
                     Q15_STEP_PER_SECTION * count + (Q15_STEP_PER_CALL if count else 0.0))
