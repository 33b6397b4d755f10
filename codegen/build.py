"""Running generated code on the host: cffi builds cached by source hash, and the CMSIS-DSP filter.

Fourth step of firmware generation (plan -> context -> render -> build -> verify ->
manifest), and a leaf of it: it takes rendered text (or a cmsis target's tables) and
imports no other step; from the design modules only the cmsis kernel's output
conversion (:func:`codegen.cmsis.q31_to_q15`). :func:`host_filter` runs a target's
code the way its description names (``codegen.targets.Target.host``).

Each distinct (header, source, flags) triple is compiled once into
``<cache>/<hash>/`` and re-imported afterwards; the cache folder is
``$HELMET_ANC_CACHE`` or ``~/.cache/helmet-anc`` (a temporary folder when neither
is writable). Builds go to a scratch folder that is renamed into place, so
concurrent test workers never see a half-built module.
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

from sysid.core.files import staged_directory

from .cmsis import q31_to_q15
from .errors import BuildError, VerificationError

__all__ = ["HOST_CFLAGS", "HOST_RUNNERS", "CmsisPackageFilter", "HostFilter", "build_host", "cache_dir", "host_filter"]

# The generated code's promise: clean C99 under these warnings. Contraction of
# a*b+c into fused multiply-adds is off so the float code matches its reference.
HOST_CFLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Wconversion", "-Werror", "-ffp-contract=off")


def cache_dir() -> Path:
    """Folder of cached host builds (created on demand)."""
    candidates = [os.environ.get("HELMET_ANC_CACHE"), str(Path.home() / ".cache" / "helmet-anc"),
                  str(Path(tempfile.gettempdir()) / "helmet-anc-cache")]
    for candidate in candidates:
        if not candidate:
            continue
        folder = Path(candidate) / "cffi"
        try:
            folder.mkdir(parents=True, exist_ok=True)
            if os.access(folder, os.W_OK):
                return folder
        except OSError:
            continue
    raise BuildError("no writable cache folder for host builds (set HELMET_ANC_CACHE)")


def _cdef(name: str, header: str) -> str:
    """cffi declarations: opaque state structs and the prototypes found in the header."""
    lines = []
    for kind in ("f32", "q15"):
        if f"{name}_{kind}_state;" in header:
            lines.append(f"typedef struct {{ ...; }} {name}_{kind}_state;")
    prototypes = re.findall(rf"^(?:void|int16_t|float) {name}_(?:f32|q15)_\w+\([^)]*\);", header,
                            flags=re.MULTILINE)
    return "\n".join(lines + prototypes)


class HostFilter:
    """A compiled generated filter: one state per variant, processing numpy blocks."""

    def __init__(self, module, name: str):
        self._ffi, self._lib, self.name = module.ffi, module.lib, name
        self._states = {}
        for kind in ("f32", "q15"):
            if hasattr(self._lib, f"{name}_{kind}_init"):
                state = self._ffi.new(f"{name}_{kind}_state *")
                getattr(self._lib, f"{name}_{kind}_init")(state)
                self._states[kind] = state

    @property
    def variants(self) -> tuple[str, ...]:
        return tuple(self._states)

    def reset(self, kind: str) -> None:
        getattr(self._lib, f"{self.name}_{kind}_reset")(self._states[kind])

    def _run(self, kind: str, x: np.ndarray, dtype, ctype: str) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=dtype)
        # Two guard samples past the end catch writes beyond n.
        y = np.full(x.size + 2, 0x5A5A if dtype == np.int16 else np.nan, dtype=dtype)
        guard = y[-2:].copy()
        getattr(self._lib, f"{self.name}_{kind}_process")(
            self._states[kind], self._ffi.cast(f"const {ctype} *", self._ffi.from_buffer(x)),
            self._ffi.cast(f"{ctype} *", self._ffi.from_buffer(y)), x.size)
        if not np.array_equal(y[-2:], guard, equal_nan=True):
            raise BuildError(f"{self.name}_{kind}_process wrote past the end of its output")
        return y[:-2]

    def process_q15(self, x: np.ndarray) -> np.ndarray:
        """Run int16 samples through NAME_q15_process (state carries over between calls)."""
        return self._run("q15", x, np.int16, "int16_t")

    def step_q15(self, x: np.ndarray) -> np.ndarray:
        """Run int16 samples through NAME_q15_step, one call per sample (state carries over, shared
        with process_q15)."""
        step, state = getattr(self._lib, f"{self.name}_q15_step"), self._states["q15"]
        return np.array([step(state, int(v)) for v in np.asarray(x, dtype=np.int16)], dtype=np.int16)

    def process_f32(self, x: np.ndarray) -> np.ndarray:
        """Run float32 samples through NAME_f32_process (state carries over between calls)."""
        return self._run("f32", x, np.float32, "float")


def build_host(name: str, header: str, source: str) -> HostFilter:
    """Compile (or reuse) the generated NAME_filter.h/.c and return a HostFilter."""
    import cffi

    flags = list(HOST_CFLAGS)
    key = hashlib.sha256("\0".join([header, source, " ".join(flags), cffi.__version__, sys.version]).encode()).hexdigest()[:20]
    module_name = f"_helmet_anc_{name}_{key}"
    root = cache_dir()
    final = root / key
    if not any(final.glob(f"{module_name}*.so")) and not any(final.glob(f"{module_name}*.pyd")):
        try:
            # Built in a staging folder renamed into the cache (sysid.core.files.staged_directory): an
            # interrupted or failed build leaves nothing; a concurrent identical build wins harmlessly.
            with staged_directory(final) as scratch:
                (scratch / f"{name}_filter.h").write_text(header, encoding="utf-8")
                (scratch / f"{name}_filter.c").write_text(source, encoding="utf-8")
                ffi = cffi.FFI()
                ffi.cdef(_cdef(name, header))
                ffi.set_source(module_name, f'#include "{name}_filter.h"', sources=[str(scratch / f"{name}_filter.c")],
                               include_dirs=[str(scratch)], extra_compile_args=flags)
                ffi.compile(tmpdir=str(scratch), verbose=False)
        except Exception as exc:  # noqa: BLE001 - compiler failures come in many types
            message = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
            raise BuildError(f"host build of {name}_filter.c failed: {message}") from None
    library = next(iter(sorted(final.glob(f"{module_name}*.so")) + sorted(final.glob(f"{module_name}*.pyd"))))
    if module_name in sys.modules:
        return HostFilter(sys.modules[module_name], name)
    spec = importlib.util.spec_from_file_location(module_name, library,
                                                  loader=importlib.machinery.ExtensionFileLoader(module_name, str(library)))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    sys.modules[module_name] = module
    return HostFilter(module, name)


class CmsisPackageFilter:
    """The ``cmsisdsp`` package's kernels run on the cmsis target's tables, as the C would on the board.

    Used to verify ``--target cmsis``, whose C needs CMSIS-DSP headers that the host
    build does not have; the delay and Q15 conversions are applied as in the template.
    """

    def __init__(self, tables):
        try:
            import cmsisdsp
        except ImportError:
            raise VerificationError("--verify with --target cmsis needs the cmsisdsp package (pip install cmsisdsp)") from None
        self._dsp, self._tables = cmsisdsp, tables
        self.reset("q15")
        self.reset("f32")

    def reset(self, kind: str) -> None:
        dsp, tables, stages = self._dsp, self._tables, len(self._tables.q31_coefficients)
        if kind == "q15":
            q31_rows = np.array(tables.q31_coefficients, np.int32).ravel()
            if tables.kernel == "q15":
                self._fixed = dsp.arm_biquad_casd_df1_inst_q15()
                rows = np.array([(r[0], 0, *r[1:]) for r in tables.q15_coefficients], np.int16).ravel()
                dsp.arm_biquad_cascade_df1_init_q15(self._fixed, stages, rows, np.zeros(4 * stages, np.int16),
                                                    tables.q15_post_shift)
            elif tables.kernel == "q31":
                self._fixed = dsp.arm_biquad_casd_df1_inst_q31()
                dsp.arm_biquad_cascade_df1_init_q31(self._fixed, stages, q31_rows, np.zeros(4 * stages, np.int32),
                                                    tables.post_shift)
            else:
                self._fixed = dsp.arm_biquad_cas_df1_32x64_ins_q31()
                dsp.arm_biquad_cas_df1_32x64_init_q31(self._fixed, stages, q31_rows, np.zeros(4 * stages, np.int64),
                                                      tables.post_shift)
            self._line_q15 = np.zeros(tables.delay, np.int16)
        else:
            self._f32 = dsp.arm_biquad_cascade_df2T_instance_f32()
            dsp.arm_biquad_cascade_df2T_init_f32(self._f32, stages, np.array(tables.f32_coefficients, np.float32).ravel(),
                                                 np.zeros(2 * stages, np.float32))
            self._line_f32 = np.zeros(tables.delay, np.float32)

    @staticmethod
    def _delay(line: np.ndarray, x: np.ndarray):
        joined = np.concatenate((line, x))
        return joined[: x.size], joined[x.size:]

    def process_q15(self, x: np.ndarray) -> np.ndarray:
        u, self._line_q15 = self._delay(self._line_q15, np.asarray(x, np.int16))
        if self._tables.kernel == "q15":
            return np.asarray(self._dsp.arm_biquad_cascade_df1_q15(self._fixed, u), np.int16)
        run = (self._dsp.arm_biquad_cascade_df1_q31 if self._tables.kernel == "q31"
               else self._dsp.arm_biquad_cas_df1_32x64_q31)
        return q31_to_q15(run(self._fixed, u.astype(np.int32) * 65536), self._tables.output_shift)

    def process_f32(self, x: np.ndarray) -> np.ndarray:
        u, self._line_f32 = self._delay(self._line_f32, np.asarray(x, np.float32))
        return np.asarray(self._dsp.arm_biquad_cascade_df2T_f32(self._f32, u), np.float32)


# How a target's code can be run on the host (``codegen.targets.Target.host``).
HOST_RUNNERS = ("cffi", "cmsisdsp")


def host_filter(runner: str, name: str, files: dict[str, str], designs: dict):
    """The generated filter ``name`` running on the host, for verification: with ``runner``
    'cffi' its rendered ``files`` compiled (:func:`build_host`), with 'cmsisdsp' the cmsisdsp
    package's kernels on the tables in ``designs["cmsis"]`` (:class:`CmsisPackageFilter`)."""
    if runner == "cffi":
        return build_host(name, files[f"{name}_filter.h"], files[f"{name}_filter.c"])
    if runner == "cmsisdsp":
        return CmsisPackageFilter(designs["cmsis"])
    raise BuildError(f"host runner must be one of {', '.join(HOST_RUNNERS)}; found {runner!r}")
