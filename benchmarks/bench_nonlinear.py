"""Benchmark of nonlinear drivers in the self-identified workflow: identify, diagnose, refine --auto.

Per shape (a tanh saturation, symmetric; an asymmetric polynomial u + a2 u^2; that polynomial behind a
first-order coupling high-pass at 2 or 20 Hz, a Wiener-Hammerstein driver: ``hp2``, ``hp20``) and level
(the third, resp. second, harmonic at the sweeps' amplitude: -15, -22, -30 dB) on a few random helmets
(``sysid.random_plant``, short sessions), as a user works: the model identified on the session,
diagnosed (is input-nonlinearity among the top two significant findings?), refined by
``refine --auto``. Reported: rms / noise floor after identification and after refinement, the
harmonic levels at the sweeps' amplitude (true; measured on the sweeps by Farina's separation; the
refined model's), the core's order against the true plant's, the refined shape (with the pre-filter's corner found), the drive limit
and the time of diagnose + refine --auto. Also how far the noise recording's input reaches
beyond the sweeps' amplitude (its peak, and the share of its samples above the sweep amplitude):
the noise recording must excite the nonlinearity at the sweeps' level for the fit to see it.
Prints Markdown.

    python benchmarks/bench_nonlinear.py [--seeds 11,12] [--paths fb,ff] [--levels -15,-22,-30]
        [--shapes tanh,poly,hp2,hp20]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sysid.core.model import Model
from sysid.diagnose import diagnose
from sysid.estimation.input_nonlinearity import harmonic_levels, sweep_harmonics
from sysid.identify import identify
from sysid.random_plant import random_session
from sysid.refine import refine_auto
from sysid.refits.machinery import REFIT_OPTIONS

SHORT = dict(noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)


def effect(shape: str, level: float, reference: float = 1.0) -> str:
    """The simulated effect: tanh at H3 = level, or u + a2 u^2 at H2 = level (levels at the sweeps' amplitude)."""
    if shape == "tanh":
        return f"input-nonlinearity:h3_db={level},h2_db=-120,tanh=1"
    # simulate states a polynomial's levels at the session's largest input: moved to the sweeps' amplitude.
    prefilter = f",prefilter_hz={shape[2:]}" if shape.startswith("hp") else ""
    return f"input-nonlinearity:h2_db={level + 20 * np.log10(reference):.2f},h3_db=-120{prefilter}"


def _form(model: Model) -> str:
    """The refined map in words: tanh or the polynomial's degree, and the pre-filter's order and corner."""
    form = model.input_nonlinearity_form or {}
    words = "tanh" if form.get("kind") == "tanh" else (
        f"poly {len(model.input_nonlinearity)}" if model.input_nonlinearity else "none")
    prefilter = form.get("prefilter")
    return words + (f" behind hp{prefilter['order']} {prefilter['corner_hz']:.1f} Hz" if prefilter else "")


def run(seed: int, path: str, shape: str, level: float) -> dict:
    probe = random_session(seed, path, **SHORT)
    sweep_amplitude = float(np.max(np.abs(probe.sweeps[0].u)))
    largest = max(float(np.max(np.abs(r.u))) for r in (probe.noise, *probe.sweeps))
    session = random_session(seed, path, effects=[effect(shape, level, largest / sweep_amplitude)], **SHORT)
    true = Model.from_dict(session.truth["plant"])
    body = session.noise.trimmed(session.spec.transient_s).u
    model = identify(session.noise, session.sweeps, path, REFIT_OPTIONS).model
    t0 = time.perf_counter()
    findings = diagnose(model, session.noise, session.sweeps)
    auto = refine_auto(model, session.noise, session.sweeps, REFIT_OPTIONS)
    seconds = time.perf_counter() - t0
    refined = auto.model
    measured = sweep_harmonics(session.sweeps)
    k = 3 if shape == "tanh" else 2
    return {
        "seed": seed, "path": path, "shape": shape, "level": level,
        "named": any(f["effect"] == "input-nonlinearity" for f in findings.significant[:2]),
        "identified": findings.comparison.ratio, "refined": auto.after.ratio,
        "true_h": harmonic_levels(true.static_input_nonlinearity, sweep_amplitude)[k],
        "measured_h": measured.levels_db[k] if measured else float("nan"),
        "model_h": harmonic_levels(refined.static_input_nonlinearity, sweep_amplitude)[k],
        "order": refined.order, "true_order": true.order, "identified_order": model.order,
        "form": _form(refined),
        "drive_limit": refined.identification.get("drive_limit_fs"),
        "noise_peak_db": 20 * np.log10(np.max(np.abs(body)) / sweep_amplitude),
        "noise_above": float(np.mean(np.abs(body) > sweep_amplitude)),
        "noise_above_half": float(np.mean(np.abs(body) > 0.5 * sweep_amplitude)),
        "steps": sum(1 for s in auto.steps if s.accepted), "seconds": seconds,
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="11,12")
    parser.add_argument("--paths", default="fb,ff")
    parser.add_argument("--levels", default="-15,-22,-30")
    parser.add_argument("--shapes", default="tanh,poly,hp2,hp20")
    args = parser.parse_args(argv)
    print("| shape | H dB | helmet | named | rms/floor identified -> refined | H true / sweeps / model (dB) "
          "| order (identified -> refined / true) | refined map | drive limit FS | noise input: peak re sweep (dB), share "
          "above the sweep's amplitude, above half | steps | time (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for shape in args.shapes.split(","):
        for level in (float(x) for x in args.levels.split(",")):
            for seed in (int(x) for x in args.seeds.split(",")):
                for path in args.paths.split(","):
                    r = run(seed, path, shape, level)
                    rows.append(r)
                    limit = "-" if r["drive_limit"] is None else f"{r['drive_limit']:.3g}"
                    print(f"| {shape} | {level:g} | {seed} {path} | {'yes' if r['named'] else 'no'} | "
                          f"{r['identified']:.1f} -> {r['refined']:.2f} | {r['true_h']:.1f} / {r['measured_h']:.1f} / "
                          f"{r['model_h']:.1f} | {r['identified_order']} -> {r['order']} / {r['true_order']} | "
                          f"{r['form']} | {limit} | {r['noise_peak_db']:.1f}, {100 * r['noise_above']:.2f} %, "
                          f"{100 * r['noise_above_half']:.1f} % | "
                          f"{r['steps']} | {r['seconds']:.0f} |", flush=True)
    refined = np.array([r["refined"] for r in rows])
    print(f"\n{len(rows)} sessions: median refined rms/floor {np.median(refined):.2f}, worst {np.max(refined):.2f}, "
          f"<= 1.5x on {int(np.sum(refined <= 1.5))}; named in the top two on {sum(r['named'] for r in rows)}; "
          f"order within +-2 of the true on {sum(abs(r['order'] - r['true_order']) <= 2 for r in rows)}; "
          f"median time {np.median([r['seconds'] for r in rows]):.0f} s")


if __name__ == "__main__":
    main()
