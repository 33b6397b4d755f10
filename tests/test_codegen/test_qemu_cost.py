"""Instruction counts from the QEMU trace (codegen.qemu_cost) on loops of known length.

Needs ``arm-none-eabi-gcc`` and ``qemu-system-arm``; skipped with the reason otherwise.
"""

import pytest

from codegen.errors import BuildError
from codegen.qemu_cost import (RegionCounts, build_m4_elf, count_regions, have_m4_tools, per_sample_cost,
                               per_sample_function_cost)

missing = have_m4_tools()
needs_m4 = pytest.mark.skipif(missing is not None, reason=f"needs {missing} (apt-get install gcc-arm-none-eabi "
                                                           "libnewlib-arm-none-eabi qemu-system-arm)")

# Three instructions per iteration, written in assembly so the compiler cannot change them:
# subs, nop, bne (the last iteration's bne falls through and still counts).
KNOWN_LOOP = r"""
#include <stdint.h>
#include "cost_mark.h"
__attribute__((noinline)) static void spin(uint32_t n)
{
    __asm__ volatile("1:\n\tsubs %0, %0, #1\n\tnop\n\tbne 1b" : "+r"(n) : : "cc");
}
int main(void)
{
    cost_mark();
    spin(10u);
    cost_mark();
    spin(110u);
    cost_mark();
    cost_mark();
    return 0;
}
"""


@needs_m4
def test_known_loop_counts_three_instructions_per_iteration(tmp_path):
    (tmp_path / "loop.c").write_text(KNOWN_LOOP)
    counts = count_regions(build_m4_elf([tmp_path / "loop.c"], tmp_path), functions=("spin",))
    assert len(counts.regions) == 3
    # Inside spin: 3 per iteration and its return (bx lr); nothing in the empty region.
    assert [f["spin"] for f in counts.functions] == [31, 331, 0]
    assert per_sample_function_cost(counts, "spin", 10, 110) == 3.0
    # 100 more iterations of 3 instructions, everything else equal.
    assert counts.regions[1] - counts.regions[0] == 300
    assert per_sample_cost(counts, 10, 110) == 3.0
    # An empty region: the marker's bx lr, then the call into the next marker (bl).
    assert counts.regions[2] == 2
    assert counts.exit_status == 0


@needs_m4
def test_failing_program_is_an_error(tmp_path):
    (tmp_path / "fail.c").write_text('#include "cost_mark.h"\nint main(void) { cost_mark(); return 3; }\n')
    with pytest.raises(BuildError, match="exited with status 3"):
        count_regions(build_m4_elf([tmp_path / "fail.c"], tmp_path))


@needs_m4
@needs_m4
def test_unknown_function_is_an_error(tmp_path):
    (tmp_path / "loop.c").write_text(KNOWN_LOOP)
    with pytest.raises(BuildError, match="has no function missing_function"):
        count_regions(build_m4_elf([tmp_path / "loop.c"], tmp_path), functions=("missing_function",))


@needs_m4
def test_compile_error_names_the_file(tmp_path):
    (tmp_path / "bad.c").write_text("int main(void) { return undefined_name; }\n")
    with pytest.raises(BuildError, match="Cortex-M4 build of cost.elf failed: .*undefined_name"):
        build_m4_elf([tmp_path / "bad.c"], tmp_path)


def test_per_sample_cost_needs_two_regions_and_growing_counts():
    counts = RegionCounts(regions=(50, 350), exit_status=0, total=1000)
    assert per_sample_cost(counts, 10, 110) == 3.0
    with pytest.raises(ValueError, match="long"):
        per_sample_cost(counts, 110, 10)
    with pytest.raises(ValueError, match="regions 1 and 2"):
        per_sample_cost(counts, 10, 110, first=1)


GENERATED_DRIVER = r"""
#include <stddef.h>
#include <stdint.h>
#include "board_io.h"
#include "cost_mark.h"
#include "fb_filter.h"
static int16_t x[N], y[N];
static const size_t sizes[] = {1u, 2u, 3u, 5u, 33u, 4u, 64u};
int main(void)
{
    fb_q15_state s;
    size_t done = 0u, k = 0u;
    if (board_io_read("in.raw", x, sizeof x) != (long)sizeof x) {
        return 1;
    }
    fb_q15_init(&s);
    cost_mark();
    while (done < N) {
        size_t m = sizes[k++ % 7u];
        m = (m < N - done) ? m : N - done;
        fb_q15_process(&s, x + done, y + done, m);
        done += m;
    }
    cost_mark();
    return board_io_write("out.raw", y, sizeof y) == 0 ? 0 : 2;
}
"""


@needs_m4
def test_generated_filter_on_the_emulator(tmp_path):
    """The generated Q15 filter on the emulated Cortex-M4 (SSAT paths) in blocks of 1 to 64 samples
    equals the bit-exact reference, and its section functions are what the trace attributes to them."""
    import numpy as np
    from conftest_codegen import appendix_a_model, model_sweeps

    from codegen.api import generate_firmware
    from codegen.plan import plan_firmware
    from codegen.reference import fixed_reference, to_q15
    from codegen.targets import get_target

    model = appendix_a_model("fb")
    plan = plan_firmware(model)
    generate_firmware(model, tmp_path / "gen")
    x = to_q15(model_sweeps(model, seconds=0.02)[0])
    (tmp_path / "driver.c").write_text(f"#define N {x.size}u\n" + GENERATED_DRIVER)
    functions = get_target("generic").variants["q15"].cost_functions("fb", plan.fixed)
    elf = build_m4_elf([tmp_path / "driver.c", tmp_path / "gen" / "fb_filter.c"], tmp_path / "build",
                       include_dirs=[tmp_path / "gen"])
    x.tofile(elf.parent / "in.raw")
    counts = count_regions(elf, functions=functions)
    assert np.array_equal(np.fromfile(elf.parent / "out.raw", np.int16), fixed_reference(plan.fixed, x))
    inside = [counts.functions[0][f] for f in functions]
    assert all(n > 0 for n in inside)
    assert sum(inside) < counts.regions[0]
