"""Where the session tasks run: a local process pool, or a Dask distributed cluster.

No scheduling of our own: ``run_local`` hands the tasks to
``concurrent.futures.ProcessPoolExecutor``; ``run_dask`` to ``dask.distributed.Client``
(an existing cluster by its address, or a client given by the caller), with Dask's own
``retries`` for tasks whose worker died. Both yield each task's row once, in completion
order, and call ``progress(done, total, row)`` after each.

Processes of the local pool are started with ``spawn``: a fresh interpreter per worker,
as Dask's worker processes are, so neither inherits the caller's threads or state.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool

from .task import SessionTask, base_row, run_session

__all__ = ["run_local", "run_dask", "default_workers", "DEFAULT_RETRIES"]

# A task is tried this many more times after its worker died under it.
DEFAULT_RETRIES = 2
# Seconds to wait for a Dask scheduler before giving up on its address.
CONNECT_TIMEOUT_S = 10


def default_workers() -> int:
    """The number of cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - platforms without sched_getaffinity
        return max(1, os.cpu_count() or 1)


def _lost_row(task: SessionTask, reason: str) -> dict:
    row = base_row(task.entry, task.digest)
    row.update(status="failed", reason=reason)
    return row


def run_local(tasks: list[SessionTask], workers: int | None = None, retries: int = DEFAULT_RETRIES,
              progress: Callable | None = None) -> Iterator[dict]:
    """Run the tasks on a pool of ``workers`` local processes (default: the cores).

    A worker process that dies breaks the whole pool (that is how ProcessPoolExecutor
    reports it); the tasks not finished then go to a new pool, at most ``retries``
    more times, and after that get a failed row saying the worker died.
    """
    workers = workers or default_workers()
    pending = list(tasks)
    total, done = len(tasks), 0
    context = multiprocessing.get_context("spawn")
    for attempt in range(retries + 1):
        if not pending:
            return
        unfinished = []
        with ProcessPoolExecutor(max_workers=min(workers, len(pending)), mp_context=context) as pool:
            futures = {pool.submit(run_session, task): task for task in pending}
            for future in as_completed(futures):
                try:
                    row = future.result()
                except BrokenProcessPool:
                    unfinished.append(futures[future])
                    continue
                except Exception as exc:  # noqa: BLE001 - e.g. a result that cannot be written: a row, not the end
                    row = _lost_row(futures[future], f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
                done += 1
                if progress:
                    progress(done, total, row)
                yield row
        pending = unfinished
    for task in pending:
        done += 1
        row = _lost_row(task, f"worker process died {retries + 1} times while running this session")
        if progress:
            progress(done, total, row)
        yield row


def run_dask(tasks: list[SessionTask], scheduler=None, retries: int = DEFAULT_RETRIES,
             progress: Callable | None = None) -> Iterator[dict]:
    """Run the tasks on a Dask distributed cluster.

    ``scheduler`` is an address (``tcp://host:8786``) or a ``dask.distributed.Client``.
    Each task is submitted with a key made of its session name and input hash, so the
    same session is never two tasks, and with ``retries`` so a task whose worker died
    runs again elsewhere. A task that still fails (e.g. ``KilledWorker``) gets a failed
    row with Dask's reason. Give workers one thread each (``--nthreads 1``): each task
    limits BLAS to one thread, and that limit is per process, not per thread. Dask's
    nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536``, which turns off glibc's
    adaptive mmap threshold: measured, identification then spends 2.4x the CPU in page
    faults (BENCHMARKS.md, Batch); set ``MALLOC_TRIM_THRESHOLD_`` and
    ``MALLOC_MMAP_THRESHOLD_`` to 33554432 in the workers' environment instead.
    """
    from dask.distributed import Client
    from dask.distributed import as_completed as dask_completed

    own_client = not isinstance(scheduler, Client)
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT_S) if own_client else scheduler
    except (OSError, TimeoutError, ValueError) as exc:
        from sysid.core.errors import HelmetAncError

        raise HelmetAncError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
    try:
        futures = {client.submit(run_session, task, key=f"session-{task.entry.name}-{task.digest[:16]}",
                                 retries=retries, pure=False): task for task in tasks}
        total, done = len(tasks), 0
        for future in dask_completed(list(futures)):
            try:
                row = future.result()
            except Exception as exc:  # noqa: BLE001 - a lost task is a row, never the end of the batch
                row = _lost_row(futures[future], f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
            future.release()
            done += 1
            if progress:
                progress(done, total, row)
            yield row
    finally:
        if own_client:
            client.close()
