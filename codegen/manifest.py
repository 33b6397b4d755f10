"""The manifest written beside generated code, and the output folder it vouches for.

Last step of firmware generation (plan -> context -> render -> build -> verify ->
manifest), and a leaf: it imports nothing of ``codegen`` but its errors. The
manifest (format ``helmet-anc/firmware-manifest@1``) is sorted JSON holding what
the plan decided, the verification figures and the sha256 of every generated file;
its presence proves that a folder holds our output, which is what lets a later run
replace it (:mod:`sysid.core.files`).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sysid.core.files import OutputRefused, check_output_directory, write_output_directory

from . import __version__
from .errors import OutputError

__all__ = ["MANIFEST_FORMAT", "Manifest", "check_output", "json_ready", "manifest_data", "manifest_text",
           "write_directory"]

MANIFEST_FORMAT = "helmet-anc/firmware-manifest@1"


@dataclass(frozen=True)
class Manifest:
    """The manifest written beside the generated code (``data`` is its JSON content)."""

    outdir: Path
    data: dict

    @property
    def name(self) -> str:
        return self.data["name"]

    @property
    def files(self) -> list[Path]:
        return [self.outdir / f for f in self.data["files"]]

    @property
    def verification(self) -> dict | None:
        return self.data["verification"]


def json_ready(value):
    """Nested data with non-finite floats (e.g. the gain of an unstable model) replaced by None."""
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def manifest_data(name: str, files: dict[str, str], verification: dict | None = None, **entries) -> dict:
    """The manifest's content: its format, the generator, ``name``, the ``entries`` (what was
    generated from what), the verification figures (None: not verified) and the sha256 of each file."""
    return {
        "format": MANIFEST_FORMAT,
        "generator": f"helmet-anc codegen {__version__}",
        "name": name,
        **entries,
        "verification": verification,
        "files": {filename: hashlib.sha256(text.encode("utf-8")).hexdigest() for filename, text in files.items()},
    }


def manifest_text(data: dict) -> str:
    """``manifest.json``'s text: sorted keys, two-space indent, no NaN or infinity, a final newline."""
    return json.dumps(data, indent=2, sort_keys=True, allow_nan=False, default=float) + "\n"


def check_output(outdir: str | os.PathLike, force: bool = False) -> None:
    """Raise OutputError unless ``outdir`` may receive generated code (the rules of
    :func:`write_directory`); checked before anything is designed."""
    try:
        check_output_directory(outdir, "manifest.json", MANIFEST_FORMAT, force=force)
    except OutputRefused as exc:
        raise OutputError(str(exc)) from None


def write_directory(outdir: str | os.PathLike, files: dict[str, str | bytes], force: bool = False) -> Path:
    """Write ``files`` (``manifest.json`` among them) as the generated-code folder ``outdir``.

    The rules are those of every helmet-anc output folder (:mod:`sysid.core.files`): a
    new folder appears complete or not at all; an existing one is written only when
    it holds nothing but a previous output our manifest proves, or with ``force``,
    and only files a manifest of ours lists are ever removed.
    """
    try:
        return write_output_directory(outdir, files, "manifest.json", MANIFEST_FORMAT, force=force)
    except OutputRefused as exc:
        raise OutputError(str(exc)) from None
