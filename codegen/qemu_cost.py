"""Instructions executed on the emulated Cortex-M4, counted from a QEMU execution trace.

The cost model of the generated code is measured, not estimated: a driver ELF is
built with ``arm-none-eabi-gcc`` against the board start-up code of ``firmware/``
and run on QEMU's ``mps2-an386`` (a Cortex-M4F) with one guest instruction per
translation block (``-singlestep``, called ``-accel tcg,one-insn-per-tb=on`` from
QEMU 8.1) and the execution log without block chaining (``-d exec,nochain``), so
each executed instruction writes exactly one ``Trace`` line with its address.

The driver marks the regions to measure by calling :data:`MARK_FUNCTION`
(``void cost_mark(void)``, defined by :data:`MARK_SOURCE`, never inlined): the
count of a region is the number of instructions executed between two successive
entries of ``cost_mark`` (the marker's own ``bx lr`` and the call into it are
included, a constant that cancels in the per-sample figure of
:func:`per_sample_cost`, the difference of two regions over different sample
counts divided by the difference of the counts).

QEMU counts instructions, not cycles: a Cortex-M4 takes 1 cycle for most
data-processing instructions (SMLAL and SMULL included), 2 for a load and 1 + pipeline
refill (1-3) for a taken branch (ARM DDI 0439B, Cortex-M4 TRM, section 3.3).

Beside the steps of firmware generation: a leaf (it imports only the errors) that the
tests and benchmarks use on rendered code.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import BuildError

__all__ = [
    "M4_ARCH",
    "M4_CFLAGS",
    "MARK_FUNCTION",
    "MARK_SOURCE",
    "RegionCounts",
    "build_m4_elf",
    "count_regions",
    "firmware_folder",
    "have_m4_tools",
    "per_sample_cost",
    "per_sample_function_cost",
]

M4_ARCH = ("-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16")
# The generated code's promise on the board compiler (design reference, "Generated C").
M4_CFLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Wconversion", "-Werror", "-ffp-contract=off", "-ffreestanding",
             *M4_ARCH)
MARK_FUNCTION = "cost_mark"
# An empty function whose entry address delimits the measured regions; the asm
# statement keeps gcc from merging or dropping calls to it.
MARK_SOURCE = """#include "cost_mark.h"
__attribute__((noinline)) void cost_mark(void)
{
    __asm__ volatile("" ::: "memory");
}
"""
MARK_HEADER = """#ifndef COST_MARK_H
#define COST_MARK_H
/* Delimits a measured region of the instruction-count driver (codegen.qemu_cost). */
void cost_mark(void);
#endif
"""
_TRACE_PC = re.compile(rb"^Trace \d+: 0x[0-9a-f]+ \[[0-9a-f]+/([0-9a-f]+)/", re.MULTILINE)


def firmware_folder() -> Path:
    """The ``firmware/`` folder of the source tree: start-up code, linker script, semihosting I/O."""
    return Path(__file__).resolve().parent.parent / "firmware"


def have_m4_tools() -> str | None:
    """None when the cross compiler and emulator are installed, else what is missing (for skips)."""
    missing = [tool for tool in ("arm-none-eabi-gcc", "arm-none-eabi-nm", "qemu-system-arm") if shutil.which(tool) is None]
    if not (firmware_folder() / "startup_mps2_an386.c").is_file():
        missing.append("firmware/startup_mps2_an386.c (a source checkout)")
    return ", ".join(missing) or None


def build_m4_elf(sources, workdir, *, include_dirs=(), cflags=M4_CFLAGS, name: str = "cost.elf") -> Path:
    """Link ``sources`` (C files; one defines ``main``) with the mps2-an386 start-up into ``workdir/name``.

    The marker (:data:`MARK_SOURCE`) is compiled in, and ``cost_mark.h`` is on the
    include path. Raises BuildError with the compiler's first error line on failure.
    """
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "cost_mark.c").write_text(MARK_SOURCE, encoding="utf-8")
    (workdir / "cost_mark.h").write_text(MARK_HEADER, encoding="utf-8")
    firmware = firmware_folder()
    elf = workdir / name
    command = ["arm-none-eabi-gcc", *cflags, f"-I{firmware}", f"-I{workdir}", *(f"-I{d}" for d in include_dirs),
               "-nostdlib", "-nostartfiles", "-T", str(firmware / "mps2_an386.ld"), "-Wl,--gc-sections",
               "-o", str(elf), *(str(s) for s in sources), str(workdir / "cost_mark.c"),
               str(firmware / "startup_mps2_an386.c"), str(firmware / "board_io_semihost.c"), "-lgcc"]
    result = subprocess.run(command, capture_output=True, text=True, check=False, timeout=300)
    if result.returncode != 0:
        errors = [line for line in result.stderr.splitlines() if "error:" in line] or result.stderr.splitlines() or ["?"]
        raise BuildError(f"Cortex-M4 build of {elf.name} failed: {errors[0]}")
    return elf


def _symbols(elf: Path) -> dict[str, tuple[int, int]]:
    """{name: (start, end)} of the ELF's function symbols (Thumb bit cleared)."""
    listing = subprocess.run(["arm-none-eabi-nm", "-S", str(elf)], capture_output=True, text=True, check=True).stdout
    table = {}
    for line in listing.splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[2] in "tTwW":
            start = int(parts[0], 16) & ~1  # Thumb function addresses carry bit 0
            table[parts[3]] = (start, start + int(parts[1], 16))
        elif len(parts) == 3 and parts[1] in "tTwW":
            start = int(parts[0], 16) & ~1
            table.setdefault(parts[2], (start, start + 2))
    return table


def _one_instruction_per_block() -> list[str]:
    """QEMU's option for one guest instruction per translation block: ``-singlestep`` until 8.0,
    ``-accel tcg,one-insn-per-tb=on`` from 8.1 (the old spelling was removed in 9.0)."""
    text = subprocess.run(["qemu-system-arm", "--version"], capture_output=True, text=True, check=False).stdout
    match = re.search(r"version (\d+)\.(\d+)", text)
    version = (int(match.group(1)), int(match.group(2))) if match else (0, 0)
    return ["-accel", "tcg,one-insn-per-tb=on"] if version >= (8, 1) else ["-singlestep"]


@dataclass(frozen=True)
class RegionCounts:
    """Instructions executed between successive ``cost_mark`` calls, and the program's exit status.

    ``functions[i]`` maps each requested function name to the instructions executed
    inside its body (its address range) during region i.
    """

    regions: tuple[int, ...]
    exit_status: int
    total: int
    functions: tuple[dict, ...] = ()


def count_regions(elf, *, functions=(), timeout: float = 600.0) -> RegionCounts:
    """Run ``elf`` on QEMU mps2-an386 and count the instructions of each marked region.

    Region i is everything executed from the i-th entry of ``cost_mark`` up to
    (not including) the (i+1)-th; for the names in ``functions`` the instructions
    executed inside each of them are counted too. The trace goes to a temporary file
    that is parsed and removed. Raises BuildError if a symbol is missing, QEMU times
    out or the program exits with a non-zero status.
    """
    elf = Path(elf)
    table = _symbols(elf)
    for symbol in (MARK_FUNCTION, *functions):
        if symbol not in table:
            raise BuildError(f"{elf.name} has no function {symbol}")
    mark = table[MARK_FUNCTION][0]
    with tempfile.TemporaryDirectory(prefix="qemu_cost.") as tmp:
        log = Path(tmp) / "exec.log"
        command = ["qemu-system-arm", "-M", "mps2-an386", "-nographic", "-monitor", "none", "-serial", "none",
                   "-semihosting-config", "enable=on,target=native", *_one_instruction_per_block(), "-d",
                   "exec,nochain", "-D", str(log), "-kernel", str(elf)]
        try:
            result = subprocess.run(command, cwd=elf.parent, capture_output=True, check=False, timeout=timeout,
                                    env={**os.environ, "LC_ALL": "C"})
        except subprocess.TimeoutExpired:
            raise BuildError(f"QEMU run of {elf.name} did not end within {timeout:g} s") from None
        if result.returncode != 0:
            raise BuildError(f"{elf.name} exited with status {result.returncode} on QEMU")
        addresses = np.array([int(pc, 16) for pc in _TRACE_PC.findall(log.read_bytes())], dtype=np.int64)
    entries = np.flatnonzero(addresses == mark)
    regions = tuple(int(b - a) for a, b in zip(entries, entries[1:]))
    per_function = []
    for a, b in zip(entries, entries[1:]):
        window = addresses[a:b]
        per_function.append({name: int(np.count_nonzero((window >= table[name][0]) & (window < table[name][1])))
                             for name in functions})
    return RegionCounts(regions=regions, exit_status=result.returncode, total=int(addresses.size),
                        functions=tuple(per_function))


def per_sample_cost(counts: RegionCounts, short: int, long: int, first: int = 0) -> float:
    """Instructions per sample from two regions: ``first`` ran ``short`` samples, the next ``long``.

    (count[first + 1] - count[first]) / (long - short): call overhead, set-up and
    the markers cancel, what remains is the cost of the sample loop.
    """
    if long <= short:
        raise ValueError(f"long ({long}) must exceed short ({short})")
    if len(counts.regions) < first + 2:
        raise ValueError(f"need regions {first} and {first + 1}; the run marked {len(counts.regions)}")
    return (counts.regions[first + 1] - counts.regions[first]) / (long - short)


def per_sample_function_cost(counts: RegionCounts, function: str, short: int, long: int, first: int = 0) -> float:
    """As :func:`per_sample_cost`, for the instructions executed inside ``function`` only."""
    if long <= short:
        raise ValueError(f"long ({long}) must exceed short ({short})")
    if len(counts.functions) < first + 2:
        raise ValueError(f"need regions {first} and {first + 1}; the run marked {len(counts.functions)}")
    return (counts.functions[first + 1][function] - counts.functions[first][function]) / (long - short)
