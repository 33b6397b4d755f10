"""Benchmark of ``helmet-anc batch``: one simulated campaign on 1 and 2 local workers and
on a 2-worker Dask LocalCluster, the same sessions each time.

Campaign: HELMETS random helmets (``sysid.random_plant``) x HEADS heads (``batch.riders``),
FB path, written as session folders (``batch.write_simulated_campaign``). Per configuration:
wall time, CPU time of all its processes, speedup over one worker, peak resident memory
per worker process. Per task: the worker's CPU seconds (the rows' ``seconds_cpu``, which
do not depend on what else the machine runs). Runner overhead per task: the same number
of empty tasks through each runner. From these, what 8000 sessions on 32 workers take.

Each local configuration runs in a fresh process of its own, so the peak memory of its
pool's workers (``RUSAGE_CHILDREN``) is not mixed with another configuration's.

Run:  python benchmarks/bench_batch.py [--helmets 10 --heads 10 --noise 20 --sweep 5 --fast]
(prints a Markdown section on stdout, progress on stderr; the defaults are the issue's 100
thesis-length sessions with the default options).
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import platform
import resource
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from batch import run_batch, write_simulated_campaign
from sysid.identify import IdentificationOptions

# Coarser grid and shorter fit blocks: about a second of CPU per short session.
FAST_OPTIONS = IdentificationOptions(gammas=tuple(range(10, 1001, 100)), orders=tuple(range(1, 9)),
                                     scan_seconds=0.5, refine_seconds=2.0)
# Columns that depend on the run, not on the data.
RUN_COLUMNS = ("seconds_load", "seconds_identify", "seconds_refine", "seconds_total", "seconds_cpu", "resumed")


def _noop(x):
    return x


def _peak_mib_self(_=None) -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _cpu_self() -> float:
    return time.process_time()


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _local_child(root, out, workers, options, queue) -> None:
    cpu0, wall0 = _children_cpu() + time.process_time(), time.perf_counter()
    result = run_batch(root, out, workers=workers, options=options)
    wall = time.perf_counter() - wall0
    cpu = _children_cpu() + time.process_time() - cpu0
    # ru_maxrss of RUSAGE_CHILDREN: the largest of this process's finished children, i.e. its pool's workers.
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    queue.put((result.rows, wall, cpu, peak))


def _local(root, out, workers, options):
    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    process = context.Process(target=_local_child, args=(root, out, workers, options, queue))
    process.start()
    outcome = queue.get()
    process.join()
    return outcome


def _dask(root, out, options):
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        client.run(_noop, 0)  # workers up before the clock starts
        cpu0 = sum(client.run(_cpu_self).values())
        wall0 = time.perf_counter()
        result = run_batch(root, out, scheduler=client, options=options)
        wall = time.perf_counter() - wall0
        cpu = sum(client.run(_cpu_self).values()) - cpu0
        peak = max(client.run(_peak_mib_self).values())
        # Overhead: the same number of empty tasks through the scheduler.
        n = len(result.rows)
        t0 = time.perf_counter()
        client.gather(client.map(_noop, range(n), pure=False))
        overhead = (time.perf_counter() - t0) / n
    return result.rows, wall, cpu, peak, overhead


def _pool_overhead(n: int, workers: int) -> float:
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        list(pool.map(_noop, range(n)))
    return (time.perf_counter() - t0) / n


def _same(runs, roots) -> bool:
    """Every data column and every model file equal across the runs."""
    tables = [[{k: v for k, v in row.items() if k not in RUN_COLUMNS} for row in rows] for rows in runs]
    models = [{row["session"]: (root / row["model_file"]).read_bytes() for row in rows if row["model_file"]}
              for rows, root in zip(runs, roots)]
    return all(t == tables[0] for t in tables) and all(m == models[0] for m in models)


def _say(message: str) -> None:
    sys.stderr.write(f"[{time.strftime('%H:%M:%S')}] {message}\n")
    sys.stderr.flush()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--helmets", type=int, default=10)
    parser.add_argument("--heads", type=int, default=10)
    parser.add_argument("--noise", type=float, default=20.0, help="noise recording length (s)")
    parser.add_argument("--sweep", type=float, default=5.0, help="sweep length (s)")
    parser.add_argument("--fast", action="store_true",
                        help="gamma step 100, orders 1..8, 0.5 s scan and 2 s refinement blocks")
    parser.add_argument("--default-sample", type=int, default=0, metavar="K",
                        help="also identify every (sessions/K)-th session with the default options on 1 worker, "
                             "for the per-task cost of the paper estimate")
    args = parser.parse_args()
    options = FAST_OPTIONS if args.fast else IdentificationOptions()
    n = args.helmets * args.heads
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "sessions"
        write_simulated_campaign(root, args.helmets, args.heads, path="fb", seed=3, noise_duration=args.noise,
                                 sweep_duration=args.sweep, sweep_silence=0.5)
        load0 = os.getloadavg()[0]
        _say(f"{n} sessions written; local pool, 1 worker")
        one = _local(root, Path(tmp) / "one", 1, options)
        _say(f"1 worker: {one[1]:.1f} s wall; local pool, 2 workers")
        two = _local(root, Path(tmp) / "two", 2, options)
        _say(f"2 workers: {two[1]:.1f} s wall; Dask LocalCluster, 2 workers")
        dask = _dask(root, Path(tmp) / "dask", options)
        _say(f"Dask: {dask[1]:.1f} s wall; empty tasks through a process pool")
        pool_overhead = _pool_overhead(n, 2)
        sample = []
        if args.default_sample:
            from batch import read_sessions

            entries = read_sessions(root)[::max(1, n // args.default_sample)][:args.default_sample]
            _say(f"{len(entries)} sessions with the default options, 1 worker")
            sample = _local(entries, Path(tmp) / "sample", 1, IdentificationOptions())[0]
        load1 = os.getloadavg()[0]
        same = _same([one[0], two[0], dask[0]], [Path(tmp) / "one", Path(tmp) / "two", Path(tmp) / "dask"])
    cpu_task = [r["seconds_cpu"] for r in one[0] if r.get("seconds_cpu") is not None]
    wall_task = [r["seconds_total"] for r in one[0]]
    failed = sum(r["status"] != "ok" for r in one[0])

    print("## Batch (issue 15)\n")
    print(f"Machine: 2 cores, 24 GiB, Python {platform.python_version()}, 2026-11-23; load average "
          f"{load0:.1f} before and {load1:.1f} after the run (the machine was shared).\n")
    print(f"Campaign: {args.helmets} random helmets x {args.heads} heads = {n} FB sessions, {args.noise:g} s noise, "
          f"two {args.sweep:g} s sweeps; options: {'fast (--fast)' if args.fast else 'defaults'}. "
          f"Same table and model files, byte for byte, in all three runs: {same}. Failed sessions: {failed}.\n")
    print("| runner | wall (s) | CPU, all processes (s) | speedup (wall) | peak memory per worker (MiB) |")
    print("|---|---|---|---|---|")
    print(f"| local pool, 1 worker | {one[1]:.1f} | {one[2]:.1f} | 1.00 | {one[3]:.0f} |")
    print(f"| local pool, 2 workers | {two[1]:.1f} | {two[2]:.1f} | {one[1] / two[1]:.2f} | {two[3]:.0f} |")
    print(f"| Dask LocalCluster, 2 worker processes | {dask[1]:.1f} | {dask[2]:.1f} | {one[1] / dask[1]:.2f} | "
          f"{dask[3]:.0f} |")
    print(f"\nPer task (1-worker run): CPU median {statistics.median(cpu_task):.2f} s, mean "
          f"{statistics.mean(cpu_task):.2f} s, largest {max(cpu_task):.2f} s; wall median "
          f"{statistics.median(wall_task):.2f} s. Runner overhead per task (empty tasks): process pool "
          f"{1000 * pool_overhead:.1f} ms (including the start of 2 interpreters), Dask {1000 * dask[4]:.1f} ms.\n")
    reasons = statistics.multimode([r["reason"] for r in one[0] if r["status"] != "ok"]) if failed else []
    if failed:
        print(f"Failed sessions and why (most frequent reason): {', '.join(r['session'] for r in one[0] if r['status'] != 'ok')}: "
              f"{reasons[0]}\n")
    per_task = statistics.mean(cpu_task)
    hours = 8000 * (per_task + dask[4]) / 32 / 3600
    print(f"On paper, 8000 such sessions on 32 Dask workers, one core each: 8000 x ({per_task:.2f} s + "
          f"{1000 * dask[4]:.1f} ms) / 32 = {hours:.2f} h.")
    default_cpu = [r["seconds_cpu"] for r in sample if r.get("seconds_cpu") is not None]
    if default_cpu:
        hours = 8000 * (statistics.mean(default_cpu) + dask[4]) / 32 / 3600
        print(f"\nDefault options on {len(default_cpu)} of the same sessions (1 worker): CPU per task mean "
              f"{statistics.mean(default_cpu):.2f} s, median {statistics.median(default_cpu):.2f} s, largest "
              f"{max(default_cpu):.2f} s; failed {sum(r['status'] != 'ok' for r in sample)}. "
              f"8000 such sessions on 32 workers: {hours:.2f} h.")


if __name__ == "__main__":
    main()
