"""The results table of a batch: one row per session, as CSV and as JSON.

Columns (``ROW_FIELDS``): session, helmet, head, condition, path; status (ok or
failed) and reason; order, delay_samples; rms, noise_floor (full-scale units, in the
validation band) and their ratio; seed_rms (the seed grid's choice); refined,
refine_steps, findings (the effects ``refine --auto`` tried, ``;``-separated);
data_quality (clipping, DC offsets); seconds per stage (wall clock) and seconds_cpu (the
worker process's CPU time for the session); model_file (relative to
OUTDIR); input_hash; resumed (taken from an earlier run).
"""

from __future__ import annotations

import csv
import io
import json

from .outputs import TABLE_FORMAT, OutputLayout, atomic_write_text
from .task import ROW_FIELDS

__all__ = ["table_csv", "table_json", "write_table"]


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)  # round-trip exact
    return str(value)


def table_csv(rows: list[dict]) -> str:
    """The rows as CSV text with a header, columns in ``ROW_FIELDS`` order."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(ROW_FIELDS)
    for row in rows:
        writer.writerow([_cell(row.get(name)) for name in ROW_FIELDS])
    return buffer.getvalue()


def table_json(rows: list[dict]) -> str:
    """The rows as JSON: ``{"format": "helmet-anc/batch-table@1", "rows": [{column: value}, ...]}``."""
    table = {"format": TABLE_FORMAT, "rows": [{name: row.get(name) for name in ROW_FIELDS} for row in rows]}
    return json.dumps(table, indent=1, allow_nan=False) + "\n"


def write_table(layout: OutputLayout, rows: list[dict]) -> None:
    atomic_write_text(layout.table_csv, table_csv(rows))
    atomic_write_text(layout.table_json, table_json(rows))
