"""Benchmark of the identification pipeline on thesis-length simulated sessions.

For each path: a session like the seed's (20 s noise with its 3 s transient, two 5 s
sweeps), written to WAV and loaded back; then the full seed grid (gamma 10..1000
step 10 x order 1..20 = 2000 candidates) timed stage by stage over several repeats
(medians), the output-error refinement, peak memory, and the figures of the
``seed-average`` and ``h1`` estimators side by side on the same session.

Run:  python benchmarks/bench_identify.py [--repeats 5]   (prints a Markdown section)

With ``--random N [--first F]`` (or ``--seeds 0-14`` / ``--seeds 0,1,5,12``) it instead runs the random helmets of seeds F..F+N-1 (``sysid.random_plant``,
thesis-length sessions: 23 s noise, two 9 s sweeps) side by side in one run: the seed's grid
alone (no latency, no refinement) and the full pipeline, each against the true plant.
"""

from __future__ import annotations

import argparse
import platform
import resource
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from sysid.estimation.grid import grid_search
from sysid.estimation.spectra import estimate_spectra
from sysid.identify import IdentificationOptions, identify
from sysid.io.recordings import load_recording
from sysid.random_plant import random_plant, random_session
from sysid.simulate import SessionSpec, simulate_session, write_session
from sysid.validation.sweeps import noise_floor, simulated_rms, sweep_spectrum

BAND = np.linspace(20.0, 1500.0, 600)


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _frf_error(model, plant):
    ratio = model.frequency_response(BAND) / plant.frequency_response(BAND)
    return float(np.max(np.abs(20 * np.log10(np.abs(ratio))))), float(np.max(np.abs(np.angle(ratio, deg=True))))


def bench_path(path: str, repeats: int, folder: Path) -> dict:
    session = simulate_session(SessionSpec(path=path, seed=2026))
    files = write_session(session, folder / path)
    t0 = time.perf_counter()
    noise = load_recording(files["noise"])
    sweeps = [load_recording(files["sweep1"]), load_recording(files["sweep2"])]
    load_s = time.perf_counter() - t0

    stages = {"spectra": [], "smoothing": [], "subspace": [], "validation": [], "grid total": []}
    for _ in range(repeats):
        t0 = time.perf_counter()
        body = noise.trimmed(3.0)
        spectra = estimate_spectra(body, "h1")
        sweep_spectra = [sweep_spectrum(s) for s in sweeps]
        t1 = time.perf_counter()
        grid = grid_search(spectra, sweep_spectra, (20.0, 5000.0))
        t2 = time.perf_counter()
        stages["spectra"].append(t1 - t0)
        for key in ("smoothing", "subspace", "validation"):
            stages[key].append(grid.stage_seconds[key])
        stages["grid total"].append(t2 - t0)

    floor = noise_floor(*sweeps)
    true_rms = simulated_rms(session.plant, sweeps)
    rows = {}
    for estimator in ("seed-average", "h1"):
        t0 = time.perf_counter()
        result = identify(noise, sweeps, path, IdentificationOptions(estimator=estimator))
        seconds = time.perf_counter() - t0
        info = result.model.identification
        rows[estimator] = {
            "seed_choice": (info["seed_choice"]["gamma"], info["seed_choice"]["order"]),
            "seed_rms": result.seed_rms,
            "seed_frf": _frf_error(result.seed_model, session.plant),
            "final_order": result.model.order,
            "final_rms": info["rms"],
            "final_frf": _frf_error(result.model, session.plant),
            "refine_s": result.stage_seconds.get("refinement", 0.0),
            "total_s": seconds,
        }
    return {"load": load_s, "stages": {k: statistics.median(v) for k, v in stages.items()},
            "grid_runs": stages["grid total"], "floor": floor, "true_rms": true_rms, "rows": rows,
            "candidates": grid.rms.size, "stable": int(np.isfinite(grid.rms).sum())}


def bench_random(seed: int, noise_seconds: float, sweep_seconds: float, full_only: bool = False) -> dict:
    """Seed grid alone and full pipeline on the random helmet ``seed``: rms / true floor, FRF error, order, delay, time
    (wall and CPU seconds, ``time.process_time``); ``full_only`` skips the grid alone."""
    rp = random_plant(seed)
    # Short sessions (the tests' 8 s / 2 s) keep the tests' 0.2 s of silence after each sweep.
    extra = {"sweep_silence": 0.2} if sweep_seconds < 5 else {}
    session = random_session(seed, noise_duration=noise_seconds, sweep_duration=sweep_seconds, **extra)
    true_floor = simulated_rms(rp.model, session.sweeps)
    f = np.geomspace(20.0, 4000.0, 2000)
    h_true = rp.model.frequency_response(f)
    out = {"seed": seed, "order": rp.order, "delay": rp.delay}
    methods = (("grid", IdentificationOptions(refine=False, latency=False)), ("full", IdentificationOptions()))
    for label, options in methods[1:] if full_only else methods:
        t0, c0 = time.perf_counter(), time.process_time()
        result = identify(session.noise, session.sweeps, "fb", options)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        model = result.model
        out[label] = {"rms": model.identification["rms"] / true_floor,
                      "frf": float(np.max(np.abs(model.frequency_response(f) - h_true)) / np.max(np.abs(h_true))),
                      "order": model.order, "delay": model.delay, "wall": wall, "cpu": cpu,
                      **_band_figures(model, rp.model)}
    return out


def _band_figures(model, truth) -> dict:
    """The model's 95 % band (``model.uncertainty``) against the true plant over 20 Hz-4 kHz: the share of its
    frequencies where |H_model - H_true| <= relative_95 |H_model| (coverage) and the median relative_95 (width);
    empty when the model has no band (the seed grid's choice)."""
    if not model.uncertainty:
        return {}
    f = np.asarray(model.uncertainty["frequencies_hz"])
    relative = np.asarray(model.uncertainty["relative_95"])
    inside = (f >= 20.0) & (f <= 4000.0)
    h_model = model.frequency_response(f[inside])
    covered = np.abs(h_model - truth.frequency_response(f[inside])) <= relative[inside] * np.abs(h_model)
    return {"coverage": float(covered.mean()), "width": float(np.median(relative[inside]))}


def _why(r: dict, label: str) -> str:
    """Which of issue 10's criteria the method missed on this plant."""
    m = r[label]
    reasons = [f"rms {m['rms']:.2f}x" if m["rms"] > 1.2 else "", f"FRF {m['frf']:.3f}" if m["frf"] > 0.05 else "",
               f"delay {m['delay'] - r['delay']:+d}" if abs(m["delay"] - r["delay"]) > 2 else ""]
    return ", ".join(x for x in reasons if x)


def _seed_list(text: str) -> list[int]:
    """Seeds from '0-14' or '0,1,5,12' (ranges and single seeds, comma-separated)."""
    seeds = []
    for part in text.split(","):
        low, _, high = part.strip().partition("-")
        seeds += list(range(int(low), int(high or low) + 1))
    return seeds


def main_random(count: int, noise_seconds: float, sweep_seconds: float, first: int = 0, full_only: bool = False,
                seeds: list[int] | None = None) -> None:
    labels = (("full", "full pipeline"),) if full_only else (("grid", "seed grid alone"), ("full", "full pipeline"))
    rows = []
    seeds = list(range(first, first + count)) if seeds is None else seeds
    for seed in seeds:
        rows.append(bench_random(seed, noise_seconds, sweep_seconds, full_only))
        r = rows[-1]
        print(f"<!-- seed {seed}: true n {r['order']} d {r['delay']}; " + "; ".join(
            f"{k} rms {r[k]['rms']:.2f}x frf {r[k]['frf']:.3f} n {r[k]['order']} d {r[k]['delay']} {r[k]['wall']:.1f} s "
            f"CPU {r[k]['cpu']:.1f} s" + (f" band {r[k]['coverage']:.2f} width {r[k]['width']:.4f}" if "coverage" in r[k] else "")
            for k, _ in labels) + " -->", flush=True)
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    selection = f"--seeds {','.join(map(str, seeds))}" if seeds != list(range(first, first + count)) else f"--random {count} --first {first}"
    print(f"\nMachine: {_cpu_model()}, {__import__('os').cpu_count()} cores, date {time.strftime('%Y-%m-%d')}. "
          f"Command: `python benchmarks/bench_identify.py {selection} --noise-seconds "
          f"{noise_seconds:g} --sweep-seconds {sweep_seconds:g}{' --full-only' if full_only else ''}`. Peak resident memory of the process: {peak_mib:.0f} MiB.\n")
    print("| method | at floor (rms <= 1.2x, FRF <= 5 %) | and delay within 2 | median / worst rms/floor | "
          "median / worst FRF error | order chosen - true (median, range) | delay error (range) | "
          "wall median / worst (s) | CPU median / worst (s) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, name in labels:
        rms = np.array([r[label]["rms"] for r in rows])
        frf = np.array([r[label]["frf"] for r in rows])
        dn = np.array([r[label]["order"] - r["order"] for r in rows])
        dd = np.array([r[label]["delay"] - r["delay"] for r in rows])
        wall = np.array([r[label]["wall"] for r in rows])
        cpu = np.array([r[label]["cpu"] for r in rows])
        ok = int(np.sum((rms <= 1.2) & (frf <= 0.05)))
        all_three = int(np.sum((rms <= 1.2) & (frf <= 0.05) & (np.abs(dd) <= 2)))
        print(f"| {name} | {ok}/{len(rows)} | {all_three}/{len(rows)} | {np.median(rms):.2f} / {rms.max():.2f} | "
              f"{np.median(frf):.3f} / {frf.max():.3f} | "
              f"{np.median(dn):+.0f} ({dn.min():+d}..{dn.max():+d}) | {dd.min():+d}..{dd.max():+d} | "
              f"{np.median(wall):.1f} / {wall.max():.1f} | {np.median(cpu):.1f} / {cpu.max():.1f} |")
    banded = [r["full"] for r in rows if "coverage" in r["full"]]
    if banded:
        coverage = np.array([b["coverage"] for b in banded])
        width = np.array([b["width"] for b in banded])
        print(f"\nFull pipeline's 95 % band (20 Hz-4 kHz, against the true plant): coverage >= 90 % on "
              f"{int(np.sum(coverage >= 0.9))}/{len(banded)} models, coverage median {np.median(coverage):.3f}, lowest "
              f"{coverage.min():.3f}; median width (relative_95) median {100 * np.median(width):.3f} %, largest "
              f"{100 * width.max():.3f} %.")
    failing = [r for r in rows if _why(r, "full")]
    if failing:
        print("\nFull pipeline failing: " + "; ".join(
            f"seed {r['seed']} ({_why(r, 'full')}; n {r['full']['order']}, true {r['order']})" for r in failing))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--random", type=int, default=0, metavar="N", help="run N random helmets instead")
    parser.add_argument("--first", type=int, default=0, help="first random helmet seed")
    parser.add_argument("--noise-seconds", type=float, default=23.0)
    parser.add_argument("--sweep-seconds", type=float, default=9.0)
    parser.add_argument("--full-only", action="store_true", help="with --random: the full pipeline only, not the grid alone")
    parser.add_argument("--seeds", type=_seed_list, default=None, metavar="LIST",
                        help="random helmets of these seeds instead of --random/--first, e.g. 0-14 or 0,1,5,12")
    args = parser.parse_args()
    if args.seeds:
        main_random(len(args.seeds), args.noise_seconds, args.sweep_seconds, full_only=args.full_only, seeds=args.seeds)
        return
    if args.random:
        main_random(args.random, args.noise_seconds, args.sweep_seconds, args.first, args.full_only)
        return
    with tempfile.TemporaryDirectory() as tmp:
        results = {path: bench_path(path, args.repeats, Path(tmp)) for path in ("fb", "ff")}
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

    print("## Identification (issue 2)\n")
    print(f"Machine: {_cpu_model()}, {__import__('os').cpu_count()} cores, Python {platform.python_version()}, "
          f"numpy {np.__version__}. Date: {time.strftime('%Y-%m-%d')}. Command: `python benchmarks/bench_identify.py "
          f"--repeats {args.repeats}`.\n")
    print("Session: simulated like the seed's (appendix-A plant, 20 s low-passed noise incl. 3 s transient, two 5 s "
          "log sweeps 20 Hz-4 kHz, output noise 2e-4 FS, input noise 2e-5 FS, 16-bit). Full seed grid: gamma 10..1000 "
          "step 10 x order 1..20.\n")
    print(f"Stage times, median of {args.repeats} runs (s):\n")
    print("| path | load 3 WAVs | spectra | smoothing | subspace (QR+SVD per gamma, 20 orders) | validation (2000 candidates) | grid total | candidates (stable) |")
    print("|---|---|---|---|---|---|---|---|")
    for path, r in results.items():
        s = r["stages"]
        print(f"| {path} | {r['load']:.3f} | {s['spectra']:.3f} | {s['smoothing']:.3f} | {s['subspace']:.3f} | "
              f"{s['validation']:.3f} | **{s['grid total']:.2f}** (min {min(r['grid_runs']):.2f}, max {max(r['grid_runs']):.2f}) | "
              f"{r['candidates']} ({r['stable']}) |")
    print(f"\nPeak resident memory of the whole benchmark process: {peak_mib:.0f} MiB.\n")
    print("Estimators on the same session (rms in FS over both sweeps, 20 Hz-4 kHz; FRF error = max over 20 Hz-1.5 kHz "
          "against the true plant):\n")
    print("| path | estimator | seed grid choice (gamma, n) | seed rms / floor | seed FRF error (dB, deg) | refined order | refined rms / floor | refined FRF error (dB, deg) | refinement s | identify total s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for path, r in results.items():
        for estimator, row in r["rows"].items():
            print(f"| {path} | {estimator} | {row['seed_choice']} | {row['seed_rms'] / r['floor']:.2f} | "
                  f"{row['seed_frf'][0]:.2f}, {row['seed_frf'][1]:.1f} | {row['final_order']} | {row['final_rms'] / r['floor']:.3f} | "
                  f"{row['final_frf'][0]:.4f}, {row['final_frf'][1]:.3f} | {row['refine_s']:.1f} | {row['total_s']:.1f} |")
        print(f"| {path} | true plant | | | | | {r['true_rms'] / r['floor']:.3f} | | | |")
    print(f"\nNoise floors (FS): fb {results['fb']['floor']:.3e}, ff {results['ff']['floor']:.3e}.")


if __name__ == "__main__":
    main()
