"""Benchmark of diagnose and refine --auto over random synthetic sessions, per effect.

For each effect, sessions with random parameters (seeded) are simulated at the
thesis's length (20 s noise, 5 s sweeps) or shorter with ``--short``; a model is
identified at the seed's published order (FB 7, FF 5), then diagnosed and
auto-refined. For the series factors (resonance, high-pass, low-pass) the model is
identified on a clean session of the same helmet and the effect appears in the new
recordings: identified on the session itself, a nominal-order model takes the
factor in and gives up a weak plant mode instead. Reports detection rate (the effect is the top significant finding),
false-alarm rate on clean sessions, parameter error, rms/noise floor before and
after refinement and the time of each step. Prints a Markdown table.

    python benchmarks/bench_diagnose.py [--sessions 4] [--short]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from sysid.diagnose import diagnose
from sysid.identify import IdentificationOptions, identify
from sysid.refine import refine_auto
from sysid.simulate import SessionSpec, simulate_session

ORDER = {"fb": 7, "ff": 5}
REFIT = IdentificationOptions(gammas=(50, 100, 200, 400), refine_seconds=5.0)


def random_effect(kind: str, rng) -> tuple[str, float | None]:
    """(spec, true value of the estimated parameter) with parameters drawn from effects.md ranges."""
    if kind == "delay":
        d = int(rng.integers(5, 50))
        return f"delay:{d}", d
    if kind == "periodic-disturbance":
        f = float(rng.choice([50.0, 60.0, 41.7]))
        return f"periodic-disturbance:{f},3,{rng.uniform(3e-4, 2e-3):.2e}", f
    if kind == "input-nonlinearity":
        h3 = float(rng.uniform(-45, -30))
        return f"input-nonlinearity:{rng.uniform(-50, -35):.1f},{h3:.1f}", h3
    if kind == "input-noise":
        snr = float(rng.uniform(3, 12))
        return f"input-noise:{snr:.1f}", snr
    if kind == "clock-drift":
        ppm = float(rng.uniform(20, 100) * rng.choice([-1, 1]))
        return f"clock-drift:{ppm:.1f}", ppm
    if kind == "time-variation":
        return f"time-variation:{rng.uniform(4, 8):.1f}", None
    if kind == "dc-offset":
        level = float(rng.uniform(0.005, 0.03))
        return f"dc-offset:{level:.4f}", level
    if kind == "clipping":
        return f"clipping:{rng.uniform(1.1, 1.6):.2f}", None
    if kind == "resonance":
        f0 = float(np.exp(rng.uniform(np.log(60.0), np.log(3600.0))))
        return f"resonance:{f0:.1f},{rng.uniform(3, 15):.2f},{rng.uniform(6, 14) * rng.choice([1, 1, -1]):.2f}", f0
    if kind == "highpass":
        corner = float(rng.uniform(10.0, 80.0))
        return f"highpass:{corner:.1f},{int(rng.integers(1, 3))}", corner
    if kind == "lowpass":
        corner = float(np.exp(rng.uniform(np.log(1000.0), np.log(16000.0))))
        return f"lowpass:{corner:.0f},{int(rng.integers(1, 3))}", corner
    raise ValueError(kind)


ESTIMATE = {"delay": "samples", "periodic-disturbance": "frequencies_hz", "input-nonlinearity": "h3_db",
            "input-noise": "input_snr_db", "clock-drift": "ppm", "dc-offset": "offset_fs", "resonance": "f0_hz",
            "highpass": "corner_hz", "lowpass": "corner_hz"}
FACTORS = ("resonance", "highpass", "lowpass")
RELATIVE = ("clock-drift", "dc-offset") + FACTORS
PATHS = {"input-nonlinearity": ("ff",), "input-noise": ("ff",)}


def run_session(path, seed, effects, spec_changes, refine, reference=False):
    session = simulate_session(SessionSpec(path=path, seed=seed, **spec_changes), effects=effects)
    known = simulate_session(SessionSpec(path=path, seed=seed, **spec_changes)) if reference else session
    # The nominal order, or the best stable one below it when the grid has none at it.
    model = identify(known.noise, known.sweeps, path,
                     IdentificationOptions(gammas=tuple(range(50, 551, 50)), orders=tuple(range(1, ORDER[path] + 1)),
                                           refine_seconds=5.0)).model
    t0 = time.perf_counter()
    findings = diagnose(model, session.noise, session.sweeps)
    t_diag = time.perf_counter() - t0
    result = {"findings": findings, "t_diagnose": t_diag, "before": findings.comparison.ratio}
    if refine:
        t0 = time.perf_counter()
        final, steps = refine_auto(model, session.noise, session.sweeps, REFIT)
        result["t_refine"] = time.perf_counter() - t0
        from sysid.compare import compare
        result["after"] = compare(final, session.sweeps).ratio
        band = np.linspace(20.0, 1500.0, 300)
        truth = session.plant.frequency_response(band)
        for key, m in (("bias_before", model), ("bias_after", final)):
            result[key] = float(np.max(np.abs(20 * np.log10(np.abs(m.frequency_response(band) / truth)))))
    return result


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sessions", type=int, default=4)
    parser.add_argument("--short", action="store_true", help="8 s noise, 2 s sweeps instead of 20 s / 5 s")
    parser.add_argument("--kinds", help="comma-separated effects to run (default: all)")
    parser.add_argument("--timing", type=int, default=0, metavar="N",
                        help="only time diagnose and refine --auto on N thesis-length sessions per path (delay:23)")
    args = parser.parse_args()
    if args.timing:
        timing(args.timing)
        return
    changes = dict(noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2) if args.short else {}
    rows = []
    clean_alarms, clean_total, clean_times = 0, 0, []
    for path in ("fb", "ff"):
        for k in range(args.sessions):
            r = run_session(path, 100 + k, [], changes, refine=False)
            clean_total += 1
            clean_alarms += bool(r["findings"].significant)
            clean_times.append(r["t_diagnose"])
    kinds = ["delay", "resonance", "highpass", "lowpass", "periodic-disturbance", "input-nonlinearity", "input-noise",
             "dc-offset", "clipping", "clock-drift", "time-variation"]
    if args.kinds:
        unknown = set(args.kinds.split(",")) - set(kinds)
        if unknown:
            parser.error(f"unknown effect(s): {', '.join(sorted(unknown))}")
        kinds = args.kinds.split(",")
    for kind in kinds:
        hits, errors, before, after, t_d, t_r, total, bias = 0, [], [], [], [], [], 0, []
        refinable = kind in ("delay", "periodic-disturbance", "input-nonlinearity", "input-noise") + FACTORS
        for path in PATHS.get(kind, ("fb", "ff")):
            for k in range(args.sessions):
                rng = np.random.default_rng([k, len(kind), ord(path[1])])
                spec, truth = random_effect(kind, rng)
                r = run_session(path, 200 + k, [spec], changes, refine=refinable, reference=kind in FACTORS)
                total += 1
                significant = r["findings"].significant
                hit = bool(significant) and significant[0]["effect"] == kind
                hits += hit
                if hit and truth is not None and kind in ESTIMATE:
                    value = significant[0]["params"][ESTIMATE[kind]]
                    value = value[0] if isinstance(value, list) else value
                    errors.append(abs(value - truth) if kind not in RELATIVE else abs(value / truth - 1) * 100)
                before.append(r["before"])
                if refinable:
                    after.append(r["after"])
                    bias.append((r["bias_before"], r["bias_after"]))
                    t_r.append(r["t_refine"])
                t_d.append(r["t_diagnose"])
        unit = {"delay": "samples", "periodic-disturbance": "Hz", "input-nonlinearity": "dB (H3)",
                "input-noise": "dB (SNR)", "clock-drift": "% of ppm", "dc-offset": "% of offset", "resonance": "% of f0",
                "highpass": "% of corner", "lowpass": "% of corner"}.get(kind, "")
        print(f"{kind}: done", file=sys.stderr, flush=True)
        rows.append(f"| {kind} | {total} | {100 * hits / total:.0f} % | "
                    f"{(f'{np.median(errors):.3g} {unit}' if errors else '-')} | {np.median(before):.2f} | "
                    f"{(f'{np.median(after):.2f}' if after else '-')} | {np.median(t_d):.2f} | "
                    f"{(f'{np.median(t_r):.1f}' if t_r else '-')} | "
                    f"{(f'{np.median([b[0] for b in bias]):.2f} -> {np.median([b[1] for b in bias]):.2f}' if bias else '-')} |")
    print(f"False alarms on clean sessions: {clean_alarms} of {clean_total} "
          f"(diagnose median {np.median(clean_times):.2f} s)\n")
    print("| effect | sessions | detected (top finding) | median parameter error | rms/floor before | "
          "rms/floor after refine --auto | diagnose (s) | refine --auto (s) | max FRF error 20 Hz-1.5 kHz (dB) |")
    print("|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))


def timing(sessions: int) -> None:
    """Seconds of diagnose (clean and delayed sessions) and refine --auto at thesis length."""
    print("| path | session | diagnose (s) | refine --auto (s) | rms/floor before -> after |")
    print("|---|---|---|---|---|")
    for path in ("fb", "ff"):
        for k in range(sessions):
            for effects in ([], ["delay:23"], ["resonance:3400,8,10"]):
                r = run_session(path, 300 + k, effects, {}, refine=bool(effects),
                                reference=any(e.startswith(FACTORS) for e in effects))
                label = "+".join(effects) or "clean"
                after = f"{r['before']:.2f} -> {r['after']:.2f}" if effects else f"{r['before']:.2f}"
                refine_s = f"{r['t_refine']:.1f}" if "t_refine" in r else "-"
                print(f"| {path} | {label} | {r['t_diagnose']:.2f} | {refine_s} | {after} |",
                      flush=True)


if __name__ == "__main__":
    main()
