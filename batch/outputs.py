"""The batch's output folder: its layout, who owns it, and atomic writes into it.

Layout of OUTDIR::

    batch.json               our marker: format tag and the options of the batch
    models/<session>.json    one helmet-anc/model@1 per identified session
    results/<session>.json   one result record per session (its table row and input hash)
    results.csv, results.json  the results table
    nominal/<helmet>_<path>.json  nominal model + uncertainty bound per helmet and path
    summary.html             the summary page

A result record is written after its model, so a record that exists with status ok
means the model beside it is complete. Every file appears whole (written beside its
name and renamed) or not at all.
"""

from __future__ import annotations

import json
from pathlib import Path

from sysid.errors import HelmetAncError

try:  # the project's one output-safety helper, when present
    from sysid.files import atomic_write_text
except ImportError:  # pragma: no cover - older trees
    from sysid.model import atomic_write_text

__all__ = ["BATCH_FORMAT", "RESULT_FORMAT", "OutputLayout", "prepare_outdir", "write_json", "read_json", "atomic_write_text"]

BATCH_FORMAT = "helmet-anc/batch@1"
RESULT_FORMAT = "helmet-anc/batch-result@1"


class OutputLayout:
    """File names inside one batch output folder (plain strings travel to workers)."""

    def __init__(self, outdir):
        self.root = Path(outdir)

    @property
    def marker(self) -> Path:
        return self.root / "batch.json"

    def model(self, name: str) -> Path:
        return self.root / "models" / f"{name}.json"

    def result(self, name: str) -> Path:
        return self.root / "results" / f"{name}.json"

    def nominal(self, helmet_path: str) -> Path:
        return self.root / "nominal" / f"{helmet_path}.json"

    @property
    def table_csv(self) -> Path:
        return self.root / "results.csv"

    @property
    def table_json(self) -> Path:
        return self.root / "results.json"

    @property
    def summary(self) -> Path:
        return self.root / "summary.html"


def prepare_outdir(outdir, inputs) -> OutputLayout:
    """Create OUTDIR (or accept one a batch wrote) and its sub-folders.

    Refused: a folder that is not empty and carries no batch marker (we never write
    into what we did not create), a file, and an OUTDIR that holds an input file.
    """
    layout = OutputLayout(outdir)
    root = layout.root
    if root.exists() and not root.is_dir():
        raise HelmetAncError(f"{root}: exists and is not a folder; give a new or earlier batch output folder")
    if root.is_dir() and any(root.iterdir()):
        marker = read_json(layout.marker) if layout.marker.is_file() else None
        if not (isinstance(marker, dict) and marker.get("format") == BATCH_FORMAT):
            raise HelmetAncError(f"{root}: folder is not empty and was not written by helmet-anc batch; "
                                 "give a new folder or an earlier batch output")
    resolved = root.resolve()
    for name in inputs:
        if resolved in Path(name).resolve().parents:
            raise HelmetAncError(f"{root}: holds the input {name}; give an output folder outside the sessions")
    try:
        for sub in ("models", "results", "nominal"):
            (root / sub).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise HelmetAncError(f"{root}: cannot create the output folder ({exc.strerror})") from None
    return layout


def write_json(path, data) -> None:
    """Sorted, indented JSON written atomically (no NaN: JSON has none)."""
    atomic_write_text(path, json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n")


def read_json(path):
    """The JSON in path, or None when it is missing or unreadable (a half-finished earlier run)."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
