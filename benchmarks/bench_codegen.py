"""Benchmark of firmware generation on the seed's appendix-A models, emulated Cortex-M4 cost.

Measures, for the FB and FF models:

1. SNR against the float64 model on two sweeps (exponential and linear,
   20 Hz-4 kHz, scaled so the float64 output peaks at -1 dBFS) of the generated
   Q15 and float32 code (host build through cffi), next to CMSIS-DSP's kernels
   from the ``cmsisdsp`` package on the same sections: plain Q31 DF1, the 32x64
   high-precision Q31 DF1 and float32 DF2T; plus the bound set by rounding the
   float64 output itself to Q15.
2. Instructions per sample on the emulated Cortex-M4 (QEMU mps2-an386, counted
   from its execution trace by :mod:`codegen.qemu_cost`) of the real ELF: the
   generated filters (per filter, per section function, and per call of one
   sample), next to CMSIS-DSP's ``arm_biquad_cascade_df1_q31`` (4x unrolled and
   plain loop) and ``arm_biquad_cas_df1_32x64_q31`` on the same sections. CMSIS-DSP
   is not installed here: those three are written from ARM's published description
   of the algorithms (``benchmarks/cmsis_df1_kernels.c``), checked bit for bit on
   the emulator against :mod:`codegen.cmsis`'s models of the kernels.
3. Cortex-M4 code/data size of each variant's filter object (``arm-none-eabi-size``).

Run ``python benchmarks/bench_codegen.py [--write BENCHMARKS.md]``; it prints the
markdown section and, with ``--write``, replaces only its own section of the file.
The measurements are in ``codegen_snr`` (1.), ``codegen_cost`` (2.) and
``codegen_size`` (3.) beside this runner, the markdown in ``codegen_markdown``.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

from codegen.qemu_cost import have_m4_tools

# The measurements, beside this runner (a script's folder is on sys.path).
from codegen_cost import measure_cmsis, measure_cmsis_target, measure_generated
from codegen_markdown import render, write_section
from codegen_size import measure_sizes
from codegen_snr import measure_snr


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="length of each sweep (s)")
    parser.add_argument("--write", type=Path, help="markdown file whose firmware section is replaced")
    args = parser.parse_args(argv)
    missing = have_m4_tools()
    if missing or shutil.which("gcc") is None:
        print(f"bench_codegen: needs {missing or 'gcc'}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="bench_codegen.") as tmp:
        work = Path(tmp)
        snr = {p: measure_snr(p, args.seconds, work) for p in ("fb", "ff")}
        generated = {p: measure_generated(p, work) for p in ("fb", "ff")}
        cmsis = {p: measure_cmsis(p, work) for p in ("fb", "ff")}
        cmsis_target = {p: measure_cmsis_target(p, work) for p in ("fb", "ff")}
        sizes = {p: measure_sizes(p, work) for p in ("fb", "ff")}
    section = render(snr, generated, cmsis, cmsis_target, sizes, args.seconds)
    print(section)
    if args.write:
        write_section(args.write, section)
    return 0


if __name__ == "__main__":
    sys.exit(main())
