"""sysid.core.board's per-section costs against a fresh measurement on the emulated Cortex-M4.

The constants in ``sysid.core.board`` (what identify's order/error/cost curve charges a model of n states)
are QEMU measurements of the generated Q15 filter; this builds the seed's two models' filters
(``codegen.qemu_cost``) and checks them. Needs ``arm-none-eabi-gcc`` and ``qemu-system-arm``; skipped with
the reason otherwise.
"""

import pytest

from codegen.api import generate_firmware
from codegen.plan import plan_firmware
from codegen.qemu_cost import build_m4_elf, count_regions, have_m4_tools, per_sample_cost
from sysid.core.board import Q15_BLOCK_PER_SECTION, Q15_STEP_PER_CALL, Q15_STEP_PER_SECTION, board_cost, sections
from sysid.core.plants import appendix_a_model

missing = have_m4_tools()
needs_m4 = pytest.mark.skipif(missing is not None, reason=f"needs {missing} (apt-get install gcc-arm-none-eabi "
                                                           "libnewlib-arm-none-eabi qemu-system-arm)")

SHORT, LONG, CALLS = 32, 288, 32
_DRIVER = r"""
#include <stddef.h>
#include <stdint.h>
#include "NAME_filter.h"
#include "cost_mark.h"
static int16_t xq[LONG], yq[LONG];
volatile int32_t sink;
int main(void)
{
    NAME_q15_state sq;
    uint32_t seed = 12345u;
    size_t i;
    int32_t sum = 0;
    for (i = 0; i < LONG; ++i) {
        seed = seed * 1664525u + 1013904223u;
        xq[i] = (int16_t)(((int32_t)(seed >> 16) - 32768) / 4);
    }
    NAME_q15_init(&sq);
    cost_mark();
    NAME_q15_process(&sq, xq, yq, SHORT);
    cost_mark();
    NAME_q15_process(&sq, xq, yq, LONG);
    cost_mark();
    for (i = 0; i < CALLS; ++i) {
        sum += NAME_q15_step(&sq, xq[i]);
    }
    cost_mark();
    sink = sum + yq[LONG - 1];
    return 0;
}
"""


def test_a_model_costs_its_second_order_sections():
    assert [sections(n) for n in (0, 1, 2, 3, 8, 333)] == [0, 1, 1, 2, 4, 167]
    cost = board_cost(8)
    assert cost.block == pytest.approx(4 * Q15_BLOCK_PER_SECTION)
    assert cost.step == pytest.approx(4 * Q15_STEP_PER_SECTION + Q15_STEP_PER_CALL)
    assert board_cost(0).step == 0.0


@needs_m4
@pytest.mark.parametrize("path", ["fb", "ff"])
def test_constants_match_the_emulated_board(path, tmp_path):
    model = appendix_a_model(path)
    count = len(plan_firmware(model, min_snr=0.0).cascade.sections)
    generate_firmware(model, tmp_path, min_snr=0.0)
    driver = tmp_path / "driver.c"
    defines = "".join(f"#define {k} {v}\n" for k, v in dict(SHORT=SHORT, LONG=LONG, CALLS=CALLS).items())
    driver.write_text(defines + _DRIVER.replace("NAME", path))
    elf = build_m4_elf([driver, tmp_path / f"{path}_filter.c"], tmp_path / "build", include_dirs=[tmp_path])
    counts = count_regions(elf)
    block = per_sample_cost(counts, SHORT, LONG, 0)
    step = counts.regions[2] / CALLS
    # The constants are per section: the model's whole filter within 10 % of what they charge it (the call's
    # fixed part and the loop's bookkeeping are shared out differently for 3 and 4 sections).
    expected = board_cost(2 * count)
    assert block == pytest.approx(expected.block, rel=0.10), (path, count, block)
    assert step == pytest.approx(expected.step, rel=0.10), (path, count, step)
