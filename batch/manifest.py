"""The sessions of a batch: a folder of session folders, or a CSV manifest.

A session is one path (fb or ff) of one helmet on one head in one fit condition: a
white-noise recording and two repeated sweeps (design.md, "Recordings").

Folder layout: every folder below SESSIONS that holds ``noise.wav``, ``sweep1.wav`` and
``sweep2.wav`` is a session; a folder holding some of them but not all is skipped, and
``find_sessions`` names it with what it lacks (the command line lists each). Its path relative to SESSIONS names it: the first part is
the helmet, the second the head (rider or dummy), the rest the fit condition; a last
part ``fb`` or ``ff`` names the path (otherwise the path is fb). ``H1/rider03/loose/ff``
is helmet H1, head rider03, condition loose, FF path.

CSV manifest: a header with the columns helmet, head, condition, path, noise, sweep1,
sweep2 (``rider`` is accepted for ``head``); file names relative to the manifest's folder.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

from sysid.core.errors import HelmetAncError
from sysid.core.model import PATHS

__all__ = ["SessionEntry", "Skipped", "read_sessions", "find_sessions", "safe_name", "SESSION_FILES", "MANIFEST_COLUMNS"]

SESSION_FILES = ("noise.wav", "sweep1.wav", "sweep2.wav")
MANIFEST_COLUMNS = ("helmet", "head", "condition", "path", "noise", "sweep1", "sweep2")


@dataclass(frozen=True)
class SessionEntry:
    """One session to identify: who and what it is, and its three files (absolute paths)."""

    helmet: str
    head: str
    condition: str
    path: str
    noise: str
    sweep1: str
    sweep2: str

    @property
    def name(self) -> str:
        """A file-name-safe identifier, unique within a batch: helmet_head_condition_path."""
        parts = [p for p in (self.helmet, self.head, self.condition, self.path) if p]
        return "_".join(safe_name(p) for p in parts)

    @property
    def files(self) -> tuple[str, str, str]:
        return (self.noise, self.sweep1, self.sweep2)


def safe_name(text: str) -> str:
    """text with every run of characters other than letters, digits, '.', '+', '-' as one '-'."""
    return re.sub(r"[^A-Za-z0-9.+-]+", "-", text).strip("-.") or "x"


@dataclass(frozen=True)
class Skipped:
    """A folder below SESSIONS that holds some session files but not all: not a session, and why."""

    folder: str  # relative to SESSIONS
    reason: str


def read_sessions(source) -> list[SessionEntry]:
    """The sessions of a folder of session folders or of a CSV manifest, in a stable order."""
    return find_sessions(source)[0]


def find_sessions(source) -> tuple[list[SessionEntry], list[Skipped]]:
    """(the sessions, the folders skipped with the reason) of a folder of session folders or of a CSV manifest
    (which skips nothing: a bad row is an error)."""
    source = Path(source)
    skipped: list[Skipped] = []
    if source.is_dir():
        entries, skipped = _from_folder(source)
    elif source.is_file():
        entries = _from_manifest(source)
    else:
        raise HelmetAncError(f"{source}: no such folder or manifest; give a folder of session folders or a CSV file")
    if not entries:
        lacking = "; ".join(f"{s.folder} {s.reason}" for s in skipped[:3]) + ("; ..." if len(skipped) > 3 else "")
        raise HelmetAncError(f"{source}: no sessions found (a session folder holds {', '.join(SESSION_FILES)})"
                             + (f"; skipped {len(skipped)} folder(s): {lacking}" if skipped else ""))
    _check_unique(source, entries)
    return entries, skipped


def _from_folder(root: Path) -> tuple[list[SessionEntry], list[Skipped]]:
    entries, skipped = [], []
    folders = sorted({p.parent for name in SESSION_FILES for p in root.rglob(name) if p.is_file()})
    for folder in folders:
        missing = [name for name in SESSION_FILES if not (folder / name).is_file()]
        if missing:
            skipped.append(Skipped(str(folder.relative_to(root)) if folder != root else ".",
                                   f"lacks {', '.join(missing)}"))
            continue
        parts = list(folder.relative_to(root).parts) if folder != root else [root.resolve().name]
        path = "fb"
        if len(parts) > 1 and parts[-1] in PATHS:
            path = parts.pop()
        helmet, head, condition = parts[0], "/".join(parts[1:2]), "/".join(parts[2:])
        files = [str((folder / name).resolve()) for name in SESSION_FILES]
        entries.append(SessionEntry(helmet, head, condition, path, *files))
    return entries, skipped


def _from_manifest(manifest: Path) -> list[SessionEntry]:
    try:
        with manifest.open(newline="", encoding="utf-8") as handle:
            rows = list(csv.DictReader(handle))
            header = [name.strip().lower() for name in (rows[0].keys() if rows else [])]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise HelmetAncError(f"{manifest}: cannot read the CSV manifest ({exc})") from None
    header = ["head" if name == "rider" else name for name in header]
    missing = [name for name in MANIFEST_COLUMNS if name not in header]
    if missing:
        raise HelmetAncError(f"{manifest}: manifest lacks column(s) {', '.join(missing)}; "
                             f"expected {', '.join(MANIFEST_COLUMNS)}")
    base = manifest.resolve().parent
    entries = []
    for line, row in enumerate(rows, start=2):
        row = {("head" if k.strip().lower() == "rider" else k.strip().lower()): (v or "").strip()
               for k, v in row.items() if k is not None}
        if not row["helmet"]:
            raise HelmetAncError(f"{manifest}: line {line}: empty helmet")
        if row["path"] not in PATHS:
            raise HelmetAncError(f"{manifest}: line {line}: path must be fb or ff; found {row['path']!r}")
        files = []
        for column in ("noise", "sweep1", "sweep2"):
            if not row[column]:
                raise HelmetAncError(f"{manifest}: line {line}: empty {column}")
            files.append(str((base / row[column]).resolve()))
        entries.append(SessionEntry(row["helmet"], row["head"], row["condition"], row["path"], *files))
    return entries


def _check_unique(source: Path, entries: list[SessionEntry]) -> None:
    seen: dict[str, SessionEntry] = {}
    for entry in entries:
        if entry.name in seen:
            raise HelmetAncError(f"{source}: two sessions have the name {entry.name!r} "
                                 "(same helmet, head, condition and path); make them distinct")
        seen[entry.name] = entry
