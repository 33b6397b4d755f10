"""Firmware generation benchmark, cost: instructions per sample on the emulated Cortex-M4.

Part of ``benchmarks/bench_codegen.py``: QEMU mps2-an386, counted from its execution
trace by :mod:`codegen.qemu_cost`, of the real ELF: the generated filters (per filter,
per section function, and per call of one sample), CMSIS-DSP's
``arm_biquad_cascade_df1_q31`` (4x unrolled and plain loop) and
``arm_biquad_cas_df1_32x64_q31`` on the same sections, and the cmsis target's
generated Q15 C. CMSIS-DSP is not installed here: those kernels are written from
ARM's published description of the algorithms (``benchmarks/cmsis_df1_kernels.c``),
checked bit for bit on the emulator against :mod:`codegen.cmsis`'s models.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from codegen.api import generate_firmware
from codegen.cmsis import q31_kernel, q31x64_kernel
from codegen.plan import plan_firmware
from codegen.qemu_cost import M4_CFLAGS, build_m4_elf, count_regions, per_sample_cost, per_sample_function_cost
from codegen.targets import get_target
from sysid.core.plants import appendix_a_model

__all__ = ["LONG", "ONE_SAMPLE_CALLS", "SHORT", "measure_cmsis", "measure_cmsis_target", "measure_generated"]

HERE = Path(__file__).resolve().parent
# Samples of the two measured calls: the per-sample cost is the difference over LONG - SHORT samples.
SHORT, LONG = 32, 288
ONE_SAMPLE_CALLS = 32


_DRIVER = r"""
#include <stddef.h>
#include <stdint.h>
#include "NAME_filter.h"
#include "cost_mark.h"
static int16_t xq[LONG], yq[LONG];
static float xf[LONG], yf[LONG];
int main(void)
{
    NAME_q15_state sq;
    NAME_f32_state sf;
    uint32_t seed = 12345u;
    size_t i;
    for (i = 0; i < LONG; ++i) {
        seed = seed * 1664525u + 1013904223u;
        xq[i] = (int16_t)(((int32_t)(seed >> 16) - 32768) / 4);
        xf[i] = (float)xq[i] / 32768.0f;
    }
    NAME_q15_init(&sq);
    NAME_f32_init(&sf);
    cost_mark();
    NAME_q15_process(&sq, xq, yq, SHORT);
    cost_mark();
    NAME_q15_process(&sq, xq, yq, LONG);
    cost_mark();
    NAME_f32_process(&sf, xf, yf, SHORT);
    cost_mark();
    NAME_f32_process(&sf, xf, yf, LONG);
    cost_mark();
    for (i = 0; i < CALLS; ++i) {
        NAME_q15_process(&sq, xq + i, yq + i, 1u);
    }
    cost_mark();
    for (i = 0; i < CALLS; ++i) {
        NAME_f32_process(&sf, xf + i, yf + i, 1u);
    }
    cost_mark();
    return 0;
}
"""

_CMSIS_DRIVER = r"""
#include <stdint.h>
#include "board_io.h"
#include "cmsis_df1_kernels.h"
#include "cost_mark.h"
static const int32_t coeffs[] = {COEFFICIENTS};
static int32_t state[4 * STAGES];
static int64_t state64[4 * STAGES];
static int32_t x[LONG], y[LONG];
static void clear(void)
{
    uint32_t i;
    for (i = 0; i < 4u * STAGES; ++i) {
        state[i] = 0;
        state64[i] = 0;
    }
}
int main(void)
{
    df1_q31_state s = {STAGES, state, coeffs, POST_SHIFT};
    df1_32x64_q31_state w = {STAGES, state64, coeffs, POST_SHIFT};
    uint32_t seed = 12345u, i;
    for (i = 0; i < LONG; ++i) {
        seed = seed * 1664525u + 1013904223u;
        x[i] = (int32_t)(((int32_t)(seed >> 16) - 32768) / 4) * 65536;
    }
    board_io_write("in.raw", x, sizeof x);
    cost_mark();
    df1_q31_unrolled(&s, x, y, SHORT);
    cost_mark();
    df1_q31_unrolled(&s, x, y, LONG);
    cost_mark();
    df1_q31_plain(&s, x, y, SHORT);
    cost_mark();
    df1_q31_plain(&s, x, y, LONG);
    cost_mark();
    df1_32x64_q31(&w, x, y, SHORT);
    cost_mark();
    df1_32x64_q31(&w, x, y, LONG);
    cost_mark();
    /* Outputs from rest, in two blocks (state carried over), checked against the Python models. */
    clear();
    df1_q31_unrolled(&s, x, y, 7u);
    df1_q31_unrolled(&s, x + 7, y + 7, LONG - 7u);
    board_io_write("unrolled.raw", y, sizeof y);
    clear();
    df1_q31_plain(&s, x, y, LONG);
    board_io_write("plain.raw", y, sizeof y);
    clear();
    df1_32x64_q31(&w, x, y, LONG);
    board_io_write("wide.raw", y, sizeof y);
    return 0;
}
"""


_CMSIS_TARGET_DRIVER = r"""
#include <stddef.h>
#include <stdint.h>
#include "board_io.h"
#include "cost_mark.h"
#include "NAME_filter.h"
static int16_t xq[LONG], yq[LONG];
int main(void)
{
    NAME_q15_state sq;
    uint32_t seed = 12345u;
    size_t i;
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
        NAME_q15_process(&sq, xq + i, yq + i, 1u);
    }
    cost_mark();
    NAME_q15_reset(&sq);
    NAME_q15_process(&sq, xq, yq, LONG);
    board_io_write("in.raw", xq, sizeof xq);
    board_io_write("out.raw", yq, sizeof yq);
    return 0;
}
"""


def _defines(**values) -> str:
    return "".join(f"#define {k} {v}\n" for k, v in values.items())


def measure_generated(path: str, workdir: Path) -> dict:
    """Emulated instructions per sample of the generated filters: whole filter, per section, one-sample calls."""
    model = appendix_a_model(path)
    plan = plan_firmware(model, min_snr=0.0)
    gen = workdir / f"{path}_m4"
    generate_firmware(model, gen, min_snr=0.0)
    driver = gen / "driver.c"
    driver.write_text(_defines(SHORT=SHORT, LONG=LONG, CALLS=ONE_SAMPLE_CALLS) + _DRIVER.replace("NAME", path))
    sections = get_target("generic").variants["q15"].cost_functions(path, plan.fixed)
    counts = count_regions(build_m4_elf([driver, gen / f"{path}_filter.c"], gen / "build", include_dirs=[gen]),
                           functions=sections)
    q15 = per_sample_cost(counts, SHORT, LONG, 0)
    return {"sections": len(plan.cascade.sections), "orders": [s.order for s in plan.cascade.sections],
            "feedback_shifts": [s.feedback_shift for s in plan.fixed.sections],
            "q15": q15, "f32": per_sample_cost(counts, SHORT, LONG, 2),
            "q15_sections": [per_sample_function_cost(counts, f, SHORT, LONG, 0) for f in sections],
            "q15_one_sample": counts.regions[4] / ONE_SAMPLE_CALLS, "f32_one_sample": counts.regions[5] / ONE_SAMPLE_CALLS}


def measure_cmsis(path: str, workdir: Path) -> dict:
    """Emulated instructions per sample and stage of the CMSIS-DSP DF1 algorithms on the cmsis target's tables."""
    tables = plan_firmware(appendix_a_model(path), target="cmsis", min_snr=0.0).cmsis
    stages = len(tables.q31_coefficients)
    coefficients = ", ".join(str(v) if v != -(2**31) else "(-2147483647 - 1)" for row in tables.q31_coefficients
                             for v in row)
    result = {"stages": stages, "post_shift": tables.post_shift}
    for label, extra in (("runtime", ()), ("constant", (f"-DDF1_CONSTANT_POST_SHIFT={tables.post_shift}u",))):
        work = workdir / f"{path}_cmsis_{label}"
        work.mkdir(parents=True)
        driver = work / "driver.c"
        driver.write_text(_defines(SHORT=SHORT, LONG=LONG, STAGES=f"{stages}u", POST_SHIFT=f"{tables.post_shift}u")
                          + _CMSIS_DRIVER.replace("COEFFICIENTS", coefficients))
        counts = count_regions(build_m4_elf([driver, HERE / "cmsis_df1_kernels.c"], work, include_dirs=[HERE],
                                            cflags=(*M4_CFLAGS, *extra)))
        x = np.fromfile(work / "in.raw", np.int32)
        for name, model in (("unrolled", q31_kernel), ("plain", q31_kernel), ("wide", q31x64_kernel)):
            if not np.array_equal(np.fromfile(work / f"{name}.raw", np.int32), model(tables, x)):
                raise RuntimeError(f"comparison kernel {name} ({label} postShift) differs from codegen.cmsis's model")
        for k, name in enumerate(("unrolled", "plain", "32x64")):
            result[f"{name}_{label}"] = per_sample_cost(counts, SHORT, LONG, 2 * k) / stages
    return result


def measure_cmsis_target(path: str, workdir: Path) -> dict:
    """Emulated instructions per sample of the cmsis target's generated Q15 C (kernel chosen at --min-snr 80),
    linked with the comparison kernels behind CMSIS-DSP's API (``benchmarks/arm_math.h``)."""
    model = appendix_a_model(path)
    plan = plan_firmware(model, target="cmsis", variant="q15")
    gen = workdir / f"{path}_cmsis_target"
    generate_firmware(model, gen, target="cmsis", variant="q15")
    driver = gen / "driver.c"
    driver.write_text(_defines(SHORT=SHORT, LONG=LONG, CALLS=ONE_SAMPLE_CALLS)
                      + _CMSIS_TARGET_DRIVER.replace("NAME", path))
    elf = build_m4_elf([driver, gen / f"{path}_filter.c", HERE / "cmsis_df1_kernels.c"], gen / "build",
                       include_dirs=[gen, HERE])
    counts = count_regions(elf)
    x = np.fromfile(elf.parent / "in.raw", np.int16)
    variant = plan.spec.variants["q15"]
    if not np.array_equal(np.fromfile(elf.parent / "out.raw", np.int16), variant.reference(plan.cmsis, x)):
        raise RuntimeError(f"{path}: the cmsis target's C on the emulator differs from its Python reference")
    q15 = per_sample_cost(counts, SHORT, LONG, 0)
    return {"kernel": plan.cmsis.kernel, "stages": len(plan.cascade.sections), "q15": q15,
            "q15_one_sample": counts.regions[2] / ONE_SAMPLE_CALLS}
