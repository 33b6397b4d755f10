"""Benchmark of ``helmet-anc batch``: one simulated campaign on 1 and 2 local workers and
on a 2-worker Dask LocalCluster, the same sessions each time.

Campaign: HELMETS random helmets (``sysid.random_plant``) x HEADS heads (``batch.riders``),
FB path, written as session folders (``batch.write_simulated_campaign``). Per configuration:
wall time, CPU time of all processes, speedup over one worker, peak resident memory per
worker process; the per-session task cost (median of the rows' seconds_total); and the
runner overhead per task, measured by running the same number of empty tasks through
each runner. From these, what 8000 sessions on 32 workers would take.

Run:  python benchmarks/bench_batch.py [--helmets 10 --heads 10 --noise 20 --sweep 5]
(prints a Markdown section; the defaults are the issue's 100 thesis-length sessions).
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

from batch import run_batch, write_simulated_campaign
from sysid.identify import IdentificationOptions


def _noop(x):
    return x


def _peak_mib_self(_=None) -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _local(root, out, workers, options):
    cpu0, wall0 = _children_cpu() + time.process_time(), time.perf_counter()
    result = run_batch(root, out, workers=workers, options=options)
    wall = time.perf_counter() - wall0
    cpu = _children_cpu() + time.process_time() - cpu0
    # ru_maxrss of RUSAGE_CHILDREN is the largest of all finished child processes.
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    return result, wall, cpu, peak


def _dask(root, out, options):
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        client.run(_noop, 0)  # workers up before the clock starts
        cpu0 = sum(client.run(lambda: time.process_time()).values())
        wall0 = time.perf_counter()
        result = run_batch(root, out, scheduler=client, options=options)
        wall = time.perf_counter() - wall0
        cpu = sum(client.run(lambda: time.process_time()).values()) - cpu0
        peak = max(client.run(_peak_mib_self).values())
        # Overhead: the same number of empty tasks through the scheduler.
        n = len(result.rows)
        t0 = time.perf_counter()
        client.gather(client.map(_noop, range(n), pure=False))
        overhead = (time.perf_counter() - t0) / n
    return result, wall, cpu, peak, overhead


def _pool_overhead(n: int, workers: int) -> float:
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
        list(pool.map(_noop, range(n)))
    return (time.perf_counter() - t0) / n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--helmets", type=int, default=10)
    parser.add_argument("--heads", type=int, default=10)
    parser.add_argument("--noise", type=float, default=20.0, help="noise recording length (s)")
    parser.add_argument("--sweep", type=float, default=5.0, help="sweep length (s)")
    parser.add_argument("--coarse", action="store_true", help="gamma step 60, orders 1..12, 3 s refinement block")
    args = parser.parse_args()
    options = IdentificationOptions(gammas=tuple(range(10, 1001, 60)), orders=tuple(range(1, 13)),
                                    refine_seconds=3.0) if args.coarse else IdentificationOptions()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "sessions"
        write_simulated_campaign(root, args.helmets, args.heads, path="fb", seed=3, noise_duration=args.noise,
                                 sweep_duration=args.sweep, sweep_silence=0.5)
        n = args.helmets * args.heads
        load0 = os.getloadavg()[0]
        one = _local(root, Path(tmp) / "one", 1, options)
        two = _local(root, Path(tmp) / "two", 2, options)
        dask = _dask(root, Path(tmp) / "dask", options)
        pool_overhead = _pool_overhead(n, 2)
        load1 = os.getloadavg()[0]
    task = statistics.median(r["seconds_total"] for r in one[0].rows)
    same = [r["rms"] for r in one[0].rows] == [r["rms"] for r in two[0].rows] == [r["rms"] for r in dask[0].rows]

    print("## Batch (issue 15)\n")
    print(f"Machine: 2 cores, 24 GiB, Python {platform.python_version()}, 2026-11-23; load average "
          f"{load0:.1f} before and {load1:.1f} after the run (the machine was shared).\n")
    print(f"Campaign: {args.helmets} random helmets x {args.heads} heads = {n} FB sessions, {args.noise:g} s noise, "
          f"two {args.sweep:g} s sweeps; options: {'coarse grid' if args.coarse else 'defaults (seed grid)'}. "
          f"Same results in all three runs: {same}. Failed sessions: {one[0].failed}.\n")
    print("| runner | wall (s) | CPU, all processes (s) | speedup (wall) | peak memory per worker (MiB) |")
    print("|---|---|---|---|---|")
    print(f"| local pool, 1 worker | {one[1]:.1f} | {one[2]:.1f} | 1.00 | {one[3]:.0f} |")
    print(f"| local pool, 2 workers | {two[1]:.1f} | {two[2]:.1f} | {one[1] / two[1]:.2f} | {two[3]:.0f} |")
    print(f"| Dask LocalCluster, 2 worker processes | {dask[1]:.1f} | {dask[2]:.1f} | {one[1] / dask[1]:.2f} | {dask[3]:.0f} |")
    print(f"\nTask cost: median {task:.2f} s per session (1 worker). Runner overhead per task (empty tasks): "
          f"process pool {1000 * pool_overhead:.1f} ms (including pool start-up), Dask {1000 * dask[4]:.1f} ms.\n")
    for label, seconds in (("these sessions", task), ("a thesis-length session at 8 s", 8.0)):
        hours = 8000 * (seconds + dask[4]) / 32 / 3600
        print(f"On paper, 8000 sessions on 32 Dask workers at {label} ({seconds:.2f} s + {1000 * dask[4]:.1f} ms "
              f"overhead each): {hours:.2f} h if the workers are as fast as these cores and the file system keeps up.")


if __name__ == "__main__":
    main()
