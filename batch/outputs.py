"""The batch's output folder: its layout, who owns it, and atomic writes into it.

Layout of OUTDIR::

    batch.json               our marker: format tag and the options of the batch
    models/<session>.json    one helmet-anc/model@1 per identified session
    results/<session>.json   one result record per session (its table row and input hash)
    results.csv, results.json  the results table
    nominal/<helmet>_<path>.json  nominal model + uncertainty bound per helmet and path
    summary.html             the summary page

A result record is written after its model, so a record that exists with status ok
means the model beside it is complete; it holds the SHA-256 of that model file. Every
file appears whole (written beside its name and renamed) or not at all.

Ownership (design.md, "Files we write"): OUTDIR is written when it is new or empty, or
when batch.json proves an earlier batch wrote it (that is what a rerun resumes) and
everything else in it is a file a batch writes and ours by its content: a JSON file
with our format tag, the table CSV with our header, the page with our generator tag,
a model still equal to the SHA-256 its record holds (a model edited since is the
user's now), or the temporary file of a write that was interrupted. Anything else is
refused unless ``force``; even then nothing that is not ours is removed.
"""

from __future__ import annotations

import json
from pathlib import Path

from sysid.core.files import PARTIAL, OutputRefused, atomic_write_text, is_ours, sha256_text

__all__ = ["BATCH_FORMAT", "RESULT_FORMAT", "TABLE_FORMAT", "TABLE_CSV_START", "OutputLayout", "prepare_outdir",
           "foreign_entries", "write_json", "read_json", "atomic_write_text"]

BATCH_FORMAT = "helmet-anc/batch@1"
RESULT_FORMAT = "helmet-anc/batch-result@1"
TABLE_FORMAT = "helmet-anc/batch-table@1"
# The table CSV's header begins with these columns (batch.task.ROW_FIELDS).
TABLE_CSV_START = "session,helmet,head,condition,path,"
_SUBFOLDERS = ("models", "results", "nominal")


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


def prepare_outdir(outdir, inputs, force: bool = False) -> OutputLayout:
    """Create OUTDIR (or accept an earlier batch's output, which a rerun resumes) and its sub-folders.

    Refused (``OutputRefused``, before any work): a file; a folder that is not empty
    and carries no batch marker, or whose marker is ours but which holds anything a
    batch did not write (see the module docstring), unless ``force``; and an OUTDIR
    that holds one of the ``inputs``, always.
    """
    layout = OutputLayout(outdir)
    root = layout.root
    if root.exists() and not root.is_dir():
        raise OutputRefused(f"-o {root}: exists and is not a folder; give a new or earlier batch output folder")
    resolved = root.resolve()
    for name in inputs:
        if resolved in Path(name).resolve().parents:
            raise OutputRefused(f"-o {root}: holds the input {name}; give an output folder outside the sessions")
    if root.is_dir() and any(root.iterdir()) and not force:
        marker = read_json(layout.marker) if layout.marker.is_file() else None
        if not (isinstance(marker, dict) and marker.get("format") == BATCH_FORMAT):
            raise OutputRefused(f"-o {root}: folder is not empty and was not written by helmet-anc batch; "
                                "give a new folder or an earlier batch output (or --force to write beside its files)")
        foreign = foreign_entries(layout)
        if foreign:
            shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
            raise OutputRefused(f"-o {root}: holds files helmet-anc batch did not write or that were edited since "
                                f"({shown}); move them out, give a new folder, or add --force to write beside them")
    try:
        for sub in _SUBFOLDERS:
            (root / sub).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputRefused(f"-o {root}: cannot create the output folder ({exc.strerror})") from None
    return layout


def _interrupted_write(path: Path) -> bool:
    # sysid.core.files.atomic_write's temporary file, left when a process was killed mid-write.
    return path.is_file() and path.name.startswith(".") and path.name.endswith(PARTIAL)


def _ours_at_top(path: Path) -> bool:
    if path.name == "results.csv":
        try:
            with path.open(encoding="utf-8") as handle:
                return handle.readline().startswith(TABLE_CSV_START)
        except (OSError, UnicodeDecodeError):
            return False
    return path.name in ("results.json", "summary.html") and is_ours(path)


def _edited_model(layout: OutputLayout, path: Path) -> bool:
    """True when the model's result record holds a SHA-256 that the model no longer has."""
    record = read_json(layout.result(path.stem))
    digest = record.get("model_sha256") if isinstance(record, dict) and record.get("format") == RESULT_FORMAT else None
    return digest is not None and sha256_text(path.read_bytes()) != digest


def foreign_entries(layout: OutputLayout) -> list[str]:
    """Names (relative to OUTDIR) of what an earlier batch's folder holds that is not a batch output of ours."""
    foreign = []
    for entry in sorted(layout.root.iterdir()):
        if entry == layout.marker or _interrupted_write(entry):
            continue
        if entry.name in _SUBFOLDERS and entry.is_dir() and not entry.is_symlink():
            for item in sorted(entry.iterdir()):
                if _interrupted_write(item):
                    continue
                ours = item.suffix == ".json" and item.is_file() and not item.is_symlink() and is_ours(item)
                if not ours or (entry.name == "models" and _edited_model(layout, item)):
                    foreign.append(f"{entry.name}/{item.name}")
        elif not (entry.is_file() and not entry.is_symlink() and _ours_at_top(entry)):
            foreign.append(entry.name)
    return foreign


def write_json(path, data) -> None:
    """Sorted, indented JSON written atomically (no NaN: JSON has none)."""
    atomic_write_text(path, json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n")


def read_json(path):
    """The JSON in path, or None when it is missing or unreadable (a half-finished earlier run)."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
