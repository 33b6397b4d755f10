"""One session's work, as a worker runs it: identify (and optionally diagnose + refine).

``run_session(task)`` takes file paths, never arrays, so a task is a few hundred bytes
through a scheduler; workers must therefore see the session files and OUTDIR under the
same paths (a shared file system). It returns one row of the results table and writes
the session's model and result record atomically into OUTDIR.

Idempotent: the input hash (SHA-256 of the three files' bytes, the path and the
options) is stored in the model and in the result record; a task whose record already
holds an ok result for the same hash returns that row without recomputing. So a task
retried after its worker died mid-way, or a rerun of the whole batch, never writes a
result twice with different contents and never loses one.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
import warnings
from dataclasses import dataclass

from threadpoolctl import threadpool_limits

from sysid.core.files import sha256_text
from sysid.identify import IdentificationOptions, identify
from sysid.io.recordings import RecordingWarning, load_recording

from .manifest import SessionEntry
from .outputs import RESULT_FORMAT, OutputLayout, read_json, write_json

__all__ = ["SessionTask", "input_hash", "run_session", "finished_row", "base_row", "ROW_FIELDS"]

# Bump when the task's outputs change meaning, so earlier outputs are redone.
TASK_VERSION = 1

ROW_FIELDS = ("session", "helmet", "head", "condition", "path", "status", "reason", "order", "delay_samples", "rms",
              "noise_floor", "rms_over_floor", "seed_rms", "refined", "refine_steps", "findings", "data_quality",
              "seconds_load", "seconds_identify", "seconds_refine", "seconds_total", "seconds_cpu", "model_file", "input_hash", "resumed")


_IDENTITY = ("session", "helmet", "head", "condition", "path")


@dataclass(frozen=True)
class SessionTask:
    """Everything a worker needs for one session: where the files are and how to identify."""

    entry: SessionEntry
    outdir: str
    options: IdentificationOptions
    refine: bool
    digest: str


def input_hash(entry: SessionEntry, options: IdentificationOptions, refine: bool) -> str:
    """SHA-256 (hex) of the three files' bytes, the path, the options and the refine flag.

    An unreadable file hashes as its name and error, so the row says why it failed and
    the session is retried once the file can be read.
    """
    digest = hashlib.sha256()
    settings = {"task_version": TASK_VERSION, "path": entry.path, "refine": refine,
                "options": dataclasses.asdict(options)}
    digest.update(json.dumps(settings, sort_keys=True).encode())
    for name in entry.files:
        digest.update(b"\0file\0")
        try:
            with open(name, "rb") as handle:
                for block in iter(lambda: handle.read(1 << 20), b""):
                    digest.update(block)
        except OSError as exc:
            digest.update(f"unreadable {name}: {exc.strerror}".encode())
    return digest.hexdigest()


def finished_row(layout: OutputLayout, entry: SessionEntry, digest: str) -> dict | None:
    """The stored row when this session was already done with these inputs (status ok), else None."""
    record = read_json(layout.result(entry.name))
    if not (isinstance(record, dict) and record.get("format") == RESULT_FORMAT and record.get("input_hash") == digest):
        return None
    row = record.get("row")
    if not (isinstance(row, dict) and row.get("status") == "ok" and layout.model(entry.name).is_file()):
        return None
    return dict(row, resumed=True)


def base_row(entry: SessionEntry, digest: str) -> dict:
    row = dict.fromkeys(ROW_FIELDS)
    row.update(session=entry.name, helmet=entry.helmet, head=entry.head, condition=entry.condition, path=entry.path,
               input_hash=digest, resumed=False)
    return row


def _data_quality(recordings) -> str:
    notes = []
    for recording in recordings:
        label = os.path.basename(recording.path)
        for channel, clipped, offset in zip(("input", "ear"), recording.clipped_fraction, recording.dc_offset):
            if clipped:
                notes.append(f"{label} {channel} clipped {100 * clipped:.2g} %")
            if offset:
                notes.append(f"{label} {channel} DC {offset:.2g} FS")
    return "; ".join(notes)


def run_session(task: SessionTask) -> dict:
    """Identify one session (and refine it with ``refine_auto`` when asked); return its row.

    A bad session never raises: its row has status ``failed`` and the reason (the
    one-line message of the error). Only a dying worker interrupts a task, and the
    scheduler runs it again.
    """
    layout = OutputLayout(task.outdir)
    entry = task.entry
    done = finished_row(layout, entry, task.digest)
    if done is not None:
        return done
    row = base_row(entry, task.digest)
    start, start_cpu = time.perf_counter(), time.process_time()
    try:
        # One BLAS thread per task: the pool's processes are the parallelism, and results do
        # not depend on how many threads a worker happens to have.
        with threadpool_limits(limits=1, user_api="blas"), warnings.catch_warnings():
            # Clipping and DC offsets are in each Recording's fields; the row reports them.
            warnings.simplefilter("ignore", RecordingWarning)
            row.update(_identify(entry, task, row, start))
            # The model first, then its record (below): a record with status ok implies a complete model.
            row.pop("_model").save(layout.model(entry.name))
            # The record keeps the model's digest: a later batch tells our model from one edited since.
            model_digest = sha256_text(layout.model(entry.name).read_bytes())
    except Exception as exc:  # noqa: BLE001 - a task must report, not raise, whatever one session does
        message = str(exc).splitlines()[0] if str(exc) else ""
        row.update({name: None for name in ROW_FIELDS if name not in _IDENTITY}, input_hash=task.digest, resumed=False)
        row.update(status="failed", reason=f"{type(exc).__name__}: {message}" if message else type(exc).__name__)
    row.pop("_model", None)
    row["seconds_total"] = time.perf_counter() - start
    # CPU seconds of the worker process: the task's cost whatever else the machine is doing.
    row["seconds_cpu"] = time.process_time() - start_cpu
    layout.result(entry.name).parent.mkdir(parents=True, exist_ok=True)
    record = {"format": RESULT_FORMAT, "input_hash": task.digest, "row": row}
    if row["status"] == "ok":
        record["model_sha256"] = model_digest
    write_json(layout.result(entry.name), record)
    return row


def _identify(entry: SessionEntry, task: SessionTask, row: dict, start: float) -> dict:
    noise = load_recording(entry.noise)
    sweeps = [load_recording(entry.sweep1), load_recording(entry.sweep2)]
    loaded = time.perf_counter()
    result = identify(noise, sweeps, entry.path, task.options)
    identified = time.perf_counter()
    model, steps = result.model, []
    if task.refine:
        from sysid.refine import refine_auto

        auto = refine_auto(model, noise, sweeps, task.options, transient_s=task.options.transient_s)
        model, steps = auto.model, [{"effect": step.effect, "accepted": bool(step.accepted)} for step in auto.steps]
    refined = time.perf_counter()
    rms = float(model.identification.get("rms", result.refined_rms or result.seed_rms))
    floor = float(result.noise_floor)
    model.identification["batch"] = {"session": entry.name, "helmet": entry.helmet, "head": entry.head,
                                     "condition": entry.condition, "input_hash": task.digest}
    return {
        "status": "ok", "reason": "", "order": model.order, "delay_samples": model.delay, "rms": rms,
        "noise_floor": floor, "rms_over_floor": rms / floor if floor > 0 else None, "seed_rms": float(result.seed_rms),
        "refined": any(step["accepted"] for step in steps),
        "refine_steps": len(steps),
        "findings": ";".join(step["effect"] + ("" if step["accepted"] else "(rejected)") for step in steps),
        "data_quality": _data_quality([noise, *sweeps]),
        "seconds_load": loaded - start, "seconds_identify": identified - loaded,
        "seconds_refine": refined - identified if task.refine else 0.0,
        "model_file": os.path.join("models", f"{entry.name}.json"), "_model": model,
    }
