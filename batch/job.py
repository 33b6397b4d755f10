"""``run_batch``: identify every session of a manifest, locally or on a Dask cluster.

1. Read the sessions (``manifest``), check OUTDIR (``outputs``), hash each session's
   inputs with the options (``task.input_hash``).
2. Sessions whose result record holds an ok result for the same hash are taken as they
   are (resume); the others become tasks for ``runners.run_local`` (a process pool) or
   ``runners.run_dask`` (a Dask distributed cluster).
3. The results table, one nominal model with its uncertainty bound per helmet and path
   (``nominal``; from the identified models of that group), and the summary page.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

from sysid.core.model import Model
from sysid.identify import IdentificationOptions

from .manifest import SessionEntry, Skipped, find_sessions, safe_name
from .nominal import NominalModel, nominal_model
from .outputs import BATCH_FORMAT, OutputLayout, atomic_write_text, prepare_outdir, write_json
from .runners import DEFAULT_RETRIES, run_dask, run_local
from .summary import write_summary
from .table import write_table
from .task import SessionTask, finished_row, input_hash

__all__ = ["BatchResult", "run_batch"]


@dataclass
class BatchResult:
    """What a batch produced: the rows (manifest order), the nominal models, the folder."""

    rows: list[dict]
    nominals: dict = field(default_factory=dict)  # (helmet, path) -> NominalModel
    layout: OutputLayout | None = None
    skipped: list[Skipped] = field(default_factory=list)  # folders below SESSIONS that are no complete session

    @property
    def failed(self) -> int:
        return sum(row["status"] != "ok" for row in self.rows)

    @property
    def resumed(self) -> int:
        return sum(bool(row["resumed"]) for row in self.rows)


def run_batch(sessions, outdir, *, workers: int | None = None, scheduler=None, refine: bool = False,
              options: IdentificationOptions | None = None, retries: int = DEFAULT_RETRIES,
              progress=None, force: bool = False) -> BatchResult:
    """Identify every session of ``sessions`` into ``outdir``; return the table and nominal models.

    ``sessions`` is a folder of session folders, a CSV manifest (see ``batch.manifest``)
    or a list of ``SessionEntry``. ``scheduler`` (an address or a
    ``dask.distributed.Client``) sends the tasks to a Dask cluster; otherwise a local
    pool of ``workers`` processes (default: the cores) runs them. ``refine`` adds
    ``refine --auto`` after identification. ``progress(done, total, row)`` is called
    after each session, resumed ones included, and first for each folder skipped (``done`` 0,
    ``row["status"]`` "skipped", ``row["reason"]`` what it lacks; also ``BatchResult.skipped``). ``outdir`` must be new, empty or an
    earlier batch's output holding nothing else (``outputs.prepare_outdir``); ``force``
    writes beside files that are not ours (never removing them).
    """
    options = options or IdentificationOptions()
    entries: list[SessionEntry]
    entries, skipped = (list(sessions), []) if isinstance(sessions, (list, tuple)) else find_sessions(sessions)
    if progress and skipped:
        for folder in skipped:
            progress(0, len(entries), {"session": folder.folder, "status": "skipped", "reason": folder.reason})
    layout = prepare_outdir(outdir, [name for entry in entries for name in entry.files], force)
    write_json(layout.marker, {"format": BATCH_FORMAT, "refine": refine, "options": asdict(options),
                               "sessions": len(entries)})
    rows: dict[str, dict] = {}
    tasks = []
    for entry in entries:
        digest = input_hash(entry, options, refine)
        done = finished_row(layout, entry, digest)
        if done is not None:
            rows[entry.name] = done
        else:
            tasks.append(SessionTask(entry, str(layout.root.resolve()), options, refine, digest))
    total = len(entries)
    if progress:
        for k, row in enumerate(rows.values(), start=1):
            progress(k, total, row)
    offset = len(rows)

    def shifted(done, _total, row):
        if progress:
            progress(offset + done, total, row)

    if tasks:
        runner = run_dask(tasks, scheduler, retries, shifted) if scheduler is not None else \
            run_local(tasks, workers, retries, shifted)
        for row in runner:
            rows[row["session"]] = row
    ordered = [rows[entry.name] for entry in entries]
    write_table(layout, ordered)
    nominals = _nominals(layout, ordered)
    write_summary(layout, ordered, nominals)
    return BatchResult(ordered, nominals, layout, skipped)


def _nominals(layout: OutputLayout, rows: list[dict]) -> dict[tuple[str, str], NominalModel]:
    """One nominal model per helmet and path with at least two identified sessions, written to nominal/."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for row in rows:
        if row["status"] == "ok":
            groups.setdefault((row["helmet"], row["path"]), []).append(row)
    nominals = {}
    for (helmet, path), members in sorted(groups.items()):
        if len(members) < 2:
            continue
        models = [Model.load(layout.root / row["model_file"]) for row in members]
        nominal = nominal_model(models, [row["session"] for row in members])
        nominals[(helmet, path)] = nominal
        target = layout.nominal(f"{safe_name(helmet)}_{path}")
        atomic_write_text(target, json.dumps(nominal.to_dict(), indent=2, allow_nan=False) + "\n")
    return nominals

