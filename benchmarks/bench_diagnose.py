"""Benchmark of diagnose and refine --auto in the self-identified workflow, on random helmets.

As a user works: a session of a random plausible helmet (``sysid.random_plant``)
with hidden effects at random parameters is simulated; the model is identified on
that very session, then diagnosed and auto-refined. Per effect (alone, and in pairs
and triples): detection rate (the effect among the top two significant findings),
median parameter error, rms / noise floor before and after ``refine --auto``, steps
taken, stop reasons, and the CPU and wall time of diagnose and refine --auto; on
clean sessions the false-alarm rate (any significant finding). Prints Markdown.

    python benchmarks/bench_diagnose.py [--sessions 2] [--thesis] [--kinds delay,clipping] [--clean 10]

``--timing N``: only the time of ``diagnose`` and ``refine --auto`` as the command runs them
(its default refit grid, ``sysid.refine.REFIT_OPTIONS``) on N thesis-length sessions (20 s noise,
5 s sweeps) of random helmets with one to three hidden effects, the model identified on each session;
prints the median and worst CPU and wall time (targets: refine --auto median <= 30 s, worst <= 60 s;
diagnose <= 2 s), and per session diagnose's CPU time by part (the comparison and each detector,
``Diagnosis.cpu_seconds``).
"""

from __future__ import annotations

import argparse
import collections
import sys
import time

import numpy as np

from sysid.core.errors import HelmetAncError
from sysid.diagnose import diagnose
from sysid.identify import IdentificationOptions, identify
from sysid.random_plant import random_session
from sysid.refine import refine_auto
from sysid.simulate import random_effect

SHORT = dict(noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)
OPTIONS = IdentificationOptions(gammas=tuple(range(10, 1001, 60)), refine_seconds=3.0)


KINDS = ["delay", "resonance", "highpass", "lowpass", "periodic-disturbance", "input-nonlinearity", "input-noise",
         "dc-offset", "clipping", "clock-drift", "time-variation"]
COMBINATIONS = [("delay", "periodic-disturbance"), ("dc-offset", "lowpass"), ("clock-drift", "input-nonlinearity"),
                ("delay", "clipping", "periodic-disturbance")]
RELATIVE = ("clock-drift", "dc-offset", "resonance", "highpass", "lowpass")


def run_session(path: str, seed: int, effects: list[str], changes: dict) -> dict:
    session = random_session(seed, path, effects=effects, **changes)
    t0 = time.perf_counter()
    model = identify(session.noise, session.sweeps, path, OPTIONS).model
    t_identify = time.perf_counter() - t0
    c0, t0 = time.process_time(), time.perf_counter()
    findings = diagnose(model, session.noise, session.sweeps)
    diag = (time.process_time() - c0, time.perf_counter() - t0)
    result = {"findings": findings, "diagnose": diag, "identify": t_identify, "before": findings.comparison.ratio}
    if effects:
        c0, t0 = time.process_time(), time.perf_counter()
        auto = refine_auto(model, session.noise, session.sweeps, OPTIONS)
        result.update(refine=(time.process_time() - c0, time.perf_counter() - t0), after=auto.after.ratio,
                      steps=len(auto.steps), stop=auto.stop_reason.split(":")[0].split(";")[0])
    return result


def timing(count: int) -> None:
    """CPU and wall time of diagnose and refine --auto (default refit grid) on thesis-length sessions."""
    rows, diag, auto, parts = [], [], [], []
    for k in range(count):
        rng = np.random.default_rng([k, 11])
        path = ("fb", "ff")[k % 2]
        case = list(rng.choice(KINDS[:-1], size=1 + k % 3, replace=False))
        drawn = [random_effect(kind, rng)[0] for kind in case]
        try:
            session = random_session(300 + k, path, effects=drawn)
            model = identify(session.noise, session.sweeps, path, OPTIONS).model
        except HelmetAncError as exc:
            print(f"timing {k}: identification failed: {exc}", file=sys.stderr, flush=True)
            continue
        c0, t0 = time.process_time(), time.perf_counter()
        findings = diagnose(model, session.noise, session.sweeps)
        diag.append((time.process_time() - c0, time.perf_counter() - t0))
        parts.append(f"{path} {300 + k}: " + ", ".join(f"{name.removesuffix('_finding').removesuffix('_findings')} {t:.2f}"
                                                      for name, t in findings.cpu_seconds.items()))
        c0, t0 = time.process_time(), time.perf_counter()
        result = refine_auto(model, session.noise, session.sweeps)
        auto.append((time.process_time() - c0, time.perf_counter() - t0))
        rows.append(f"| {path} {300 + k} | {', '.join(drawn)} | {findings.comparison.ratio:.2f} | "
                    f"{result.after.ratio:.2f} | {len(result.steps)} | {result.stop_reason} | "
                    f"{diag[-1][0]:.2f} / {diag[-1][1]:.2f} | {auto[-1][0]:.1f} / {auto[-1][1]:.1f} |")
        print(rows[-1], file=sys.stderr, flush=True)
    print("| session | hidden effects | rms/floor before | after refine --auto | steps | stop reason | "
          "diagnose CPU / wall (s) | refine --auto CPU / wall (s) |")
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    if auto:
        cpu, wall = np.array([a[0] for a in auto]), np.array([a[1] for a in auto])
        print(f"\nrefine --auto CPU median {np.median(cpu):.1f} s, worst {cpu.max():.1f} s; wall median "
              f"{np.median(wall):.1f} s, worst {wall.max():.1f} s; diagnose CPU median "
              f"{np.median([d[0] for d in diag]):.2f} s, worst {max(d[0] for d in diag):.2f} s, wall median "
              f"{np.median([d[1] for d in diag]):.2f} s, worst {max(d[1] for d in diag):.2f} s ({len(auto)} sessions)")
        print("\ndiagnose CPU by part (s):\n" + "\n".join(f"- {line}" for line in parts))


def error_of(kind, value, truth):
    value = value[0] if isinstance(value, list) else value
    return abs(value / truth - 1) * 100 if kind in RELATIVE else abs(value - truth)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sessions", type=int, default=2, help="sessions per effect and path")
    parser.add_argument("--clean", type=int, default=10, help="clean sessions per path")
    parser.add_argument("--thesis", action="store_true", help="20 s noise, 5 s sweeps instead of 8 s / 2 s")
    parser.add_argument("--kinds", help="comma-separated effects (default: all, then the combinations)")
    parser.add_argument("--timing", type=int, help="only time diagnose and refine --auto on this many thesis-length sessions")
    args = parser.parse_args()
    if args.timing:
        timing(args.timing)
        return
    changes = {} if args.thesis else SHORT
    cases = [(k,) for k in (args.kinds.split(",") if args.kinds else KINDS)]
    cases += [] if args.kinds else COMBINATIONS
    alarms, clean, clean_times = 0, 0, []
    for path in ("fb", "ff"):
        for k in range(args.clean):
            try:
                r = run_session(path, 1000 + k, [], changes)
            except HelmetAncError as exc:
                print(f"clean {path} {k}: failed: {exc}", file=sys.stderr, flush=True)
                continue
            clean += 1
            alarms += bool(r["findings"].significant)
            clean_times.append(r["diagnose"])
            print(f"clean {path} {k}: {r['before']:.2f}x {[f['effect'] for f in r['findings'].significant]}",
                  file=sys.stderr, flush=True)
    rows = []
    for case in cases:
        stats = collections.defaultdict(list)
        for path in ("fb", "ff"):
            for k in range(args.sessions):
                rng = np.random.default_rng([k, sum(map(len, case)), ord(path[1])])
                drawn = [random_effect(kind, rng) for kind in case]
                try:
                    r = run_session(path, 200 + k, [d[0] for d in drawn], changes)
                except HelmetAncError as exc:
                    # An identification that fails is counted and said, not hidden.
                    stats["failed"].append(f"{path}: {exc}")
                    print(f"{'+'.join(case)} {path} {k}: failed: {exc}", file=sys.stderr, flush=True)
                    continue
                top_two = [f for f in r["findings"].significant[:2]]
                for kind, (_, name, truth) in zip(case, drawn):
                    hit = next((f for f in top_two if f["effect"] == kind), None)
                    stats["hits"].append(hit is not None)
                    if hit is not None and name is not None and name in hit["params"]:
                        stats["errors"].append(error_of(kind, hit["params"][name], truth))
                stats["before"].append(r["before"])
                stats["after"].append(r["after"])
                stats["steps"].append(r["steps"])
                stats["stop"].append(r["stop"])
                stats["diag_cpu"].append(r["diagnose"][0])
                stats["refine_cpu"].append(r["refine"][0])
                stats["refine_wall"].append(r["refine"][1])
                stats["identify"].append(r["identify"])
                print(f"{'+'.join(case)} {path} {k}: {[d[0] for d in drawn]} {r['before']:.2f}x -> {r['after']:.2f}x "
                      f"[{r['stop']}] found {[f['effect'] for f in top_two]}", file=sys.stderr, flush=True)
        if not stats["before"]:
            rows.append(f"| {' + '.join(case)} | 0 | identification failed: {'; '.join(stats['failed'])} |")
            continue
        at_floor = np.mean(np.array(stats["after"]) <= 1.2)
        error = f"{np.median(stats['errors']):.3g}" if stats["errors"] else "-"
        stops = ", ".join(f"{n} {s}" for s, n in collections.Counter(stats["stop"]).most_common())
        rows.append(f"| {' + '.join(case)} | {len(stats['before'])} | {100 * np.mean(stats['hits']):.0f} % | "
                    f"{error} | "
                    f"{np.median(stats['before']):.2f} | {np.median(stats['after']):.2f} | {100 * at_floor:.0f} % | "
                    f"{np.median(stats['steps']):.0f} | {np.median(stats['diag_cpu']):.2f} | "
                    f"{np.median(stats['refine_cpu']):.1f} / {np.max(stats['refine_cpu']):.1f} | "
                    f"{np.median(stats['identify']):.1f} | {stops} |")
    if clean:
        print(f"Clean random helmets with a significant finding: {alarms} of {clean}; diagnose CPU "
              f"median {np.median([t[0] for t in clean_times]):.2f} s\n")
    print("| effects | sessions | among top two | median parameter error | rms/floor before | after refine --auto | "
          "at most 1.2x after | steps (median) | diagnose CPU (s) | refine --auto CPU median / max (s) | identify (s) | "
          "stop reasons |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
