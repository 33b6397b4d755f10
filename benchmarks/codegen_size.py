"""Firmware generation benchmark, size: Cortex-M4F code and data of each variant's filter object.

Part of ``benchmarks/bench_codegen.py``: ``arm-none-eabi-size`` of the generated
filter compiled with the board's flags.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from codegen.api import generate_firmware
from codegen.qemu_cost import M4_CFLAGS
from sysid.core.plants import appendix_a_model

__all__ = ["measure_sizes"]


def measure_sizes(path: str, workdir: Path) -> dict:
    """Code/data size (bytes) of each variant's filter object for the Cortex-M4F."""
    result = {}
    model = appendix_a_model(path)
    for variant in ("q15", "float"):
        gen = workdir / f"{path}_size_{variant}"
        generate_firmware(model, gen, variant=variant, min_snr=0.0)
        subprocess.run(["arm-none-eabi-gcc", *M4_CFLAGS, "-c", "-o", "filter.o", f"{path}_filter.c"], cwd=gen,
                       check=True, timeout=120)
        size = subprocess.run(["arm-none-eabi-size", "filter.o"], cwd=gen, capture_output=True, text=True, check=True)
        text, data, bss = (int(v) for v in size.stdout.splitlines()[1].split()[:3])
        result[variant] = {"text": text, "data": data, "bss": bss}
    return result
