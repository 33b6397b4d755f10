"""Host build of generated C through cffi (API mode), cached by source hash.

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

from .errors import BuildError

__all__ = ["HOST_CFLAGS", "HostFilter", "build_host", "cache_dir"]

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
