"""Benchmark of nonlinear drivers in the self-identified workflow: identify, diagnose, refine --auto.

Per shape and level on a few helmets (random helmets of ``sysid.random_plant`` by seed, or the seed's
appendix-A FB and FF plants with ``--plants seed``; short sessions), as a user works: the model identified
on the session, diagnosed (is input-nonlinearity among the top two significant findings?), refined by
``refine --auto``. Shapes, the level being the harmonic's at the sweeps' amplitude (dB re the fundamental):

- ``tanh``: a symmetric saturation s tanh(u/s), H3 at the level;
- ``tanh-asym``: that tanh with an offset, s tanh((u + o)/s) - s tanh(o/s), H3 and H2 both at the level
  (where the offset cannot reach H2, the largest it gives);
- ``poly``: u + a2 u^2, H2 at the level; ``hp2``, ``hp20``: that polynomial behind a first-order coupling
  high-pass at 2 or 20 Hz (a Wiener-Hammerstein driver);
- ``cubic+``: u + a3 u^3 (an expanding map, a softening suspension), ``cubic-``: u - a3 u^3 (a compressing
  one, a hardening suspension), H3 at the level;
- ``mixed``: u + a2 u^2 + a3 u^3 with H2 and H3 both at the level.

With ``--at largest`` a polynomial's level holds at the session's largest input instead (``simulate``'s own
convention): where the noise recording peaks far above the sweeps (the seed's FB plant: about 18 dB), a cubic
stated at the sweeps' amplitude would reach H3 above 0 dB at those peaks, a map no driver has.

Reported: rms / noise floor after identification and after refinement, the H2 and H3 levels at the
sweeps' amplitude (true; measured on the sweeps by Farina's separation; the refined model's), the core's
order against the true plant's, the refined shape (with the pre-filter's corner found), the drive limit and
the time of diagnose + refine --auto. Also how far the noise recording's input reaches beyond the sweeps'
amplitude (its peak, and the share of its samples above the sweep amplitude): the noise recording must
excite the nonlinearity at the sweeps' level for the fit to see it. A case whose workflow raises is
reported with its error, and the run goes on. Prints Markdown.

    python benchmarks/bench_nonlinear.py [--plants random|seed] [--at sweeps|largest] [--seeds 11,12] [--paths fb,ff]
        [--levels -15,-22,-30] [--shapes tanh,tanh-asym,poly,hp2,hp20,cubic+,cubic-,mixed]
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
from sysid.simulate import SessionSpec, simulate_session
from sysid.refine import refine_auto
from sysid.refits.machinery import REFIT_OPTIONS

SHORT = dict(noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)


SHAPES = ("tanh", "tanh-asym", "poly", "hp2", "hp20", "cubic+", "cubic-", "mixed")


def effect(shape: str, level: float, reference: float = 1.0) -> str:
    """The simulated effect of ``shape`` at ``level`` dB (at the sweeps' amplitude); ``reference``: the session's
    largest input over the sweeps' amplitude (``simulate`` states a polynomial's levels at the largest input)."""
    if shape == "tanh":
        return f"input-nonlinearity:h3_db={level},h2_db=-120,tanh=1"
    if shape == "tanh-asym":
        from sysid.estimation.input_nonlinearity import saturation_form

        try:  # the offset's reach: a tanh of a given H3 has a largest H2.
            saturation_form(level, level, 1.0)
            h2 = level
        except ValueError:
            h2 = _largest_h2(level)
        return f"input-nonlinearity:h3_db={level},h2_db={h2:.2f},tanh=1"
    # A polynomial's H2 scales with the amplitude, its H3 with the amplitude squared.
    h2 = level + 20 * np.log10(reference)
    h3 = level + 40 * np.log10(reference)
    if shape in ("cubic+", "cubic-"):
        return f"input-nonlinearity:h2_db=-120,h3_db={h3:.2f},compressive={int(shape == 'cubic-')}"
    if shape == "mixed":
        return f"input-nonlinearity:h2_db={h2:.2f},h3_db={h3:.2f}"
    prefilter = f",prefilter_hz={shape[2:]}" if shape.startswith("hp") else ""
    return f"input-nonlinearity:h2_db={h2:.2f},h3_db=-120{prefilter}"


def _largest_h2(h3_db: float) -> float:
    """The largest H2 (dB) an offset tanh of third harmonic ``h3_db`` gives, less 0.5 dB."""
    from sysid.estimation.input_nonlinearity import harmonic_levels, saturation_form, tanh_map

    scale = saturation_form(h3_db, -120.0, 1.0)["scale"]
    return harmonic_levels(lambda u: tanh_map(u, scale, 3.0 * scale), 1.0)[2] - 0.5


def session_of(plants: str, seed: int, path: str, effects=()):
    """The short session of a random helmet (``plants`` "random") or of the seed's appendix-A plant ("seed")."""
    if plants == "seed":
        return simulate_session(SessionSpec(path=path, seed=seed, **SHORT), effects=effects)
    return random_session(seed, path, effects=effects, **SHORT)


def _form(model: Model) -> str:
    """The refined map in words: tanh or the polynomial's degree, and the pre-filter's order and corner."""
    form = model.input_nonlinearity_form or {}
    words = "tanh" if form.get("kind") == "tanh" else (
        f"poly {len(model.input_nonlinearity)}" if model.input_nonlinearity else "none")
    prefilter = form.get("prefilter")
    return words + (f" behind hp{prefilter['order']} {prefilter['corner_hz']:.1f} Hz" if prefilter else "")


def run(seed: int, path: str, shape: str, level: float, plants: str = "random", at: str = "sweeps") -> dict:
    probe = session_of(plants, seed, path)
    sweep_amplitude = float(np.max(np.abs(probe.sweeps[0].u)))
    largest = max(float(np.max(np.abs(r.u))) for r in (probe.noise, *probe.sweeps))
    reference = largest / sweep_amplitude if at == "sweeps" else 1.0
    session = session_of(plants, seed, path, [effect(shape, level, reference)])
    true = Model.from_dict(session.truth["plant"])
    body = session.noise.trimmed(session.spec.transient_s).u
    model = identify(session.noise, session.sweeps, path, REFIT_OPTIONS).model
    t0 = time.perf_counter()
    findings = diagnose(model, session.noise, session.sweeps)
    auto = refine_auto(model, session.noise, session.sweeps, REFIT_OPTIONS)
    seconds = time.perf_counter() - t0
    refined = auto.model
    measured = sweep_harmonics(session.sweeps)
    true_h = harmonic_levels(true.static_input_nonlinearity, sweep_amplitude)
    model_h = harmonic_levels(refined.static_input_nonlinearity, sweep_amplitude)
    return {
        "seed": seed, "path": path, "shape": shape, "level": level, "error": None,
        "named": any(f["effect"] == "input-nonlinearity" for f in findings.significant[:2]),
        "top": [f["effect"] for f in findings.significant[:2]],
        "identified": findings.comparison.ratio, "refined": auto.after.ratio,
        "true_h": {k: true_h[k] for k in (2, 3)},
        "measured_h": {k: measured.levels_db[k] if measured else float("nan") for k in (2, 3)},
        "model_h": {k: model_h[k] for k in (2, 3)},
        "order": refined.order, "true_order": true.order, "identified_order": model.order,
        "form": _form(refined),
        "drive_limit": refined.identification.get("drive_limit_fs"),
        "noise_peak_db": 20 * np.log10(np.max(np.abs(body)) / sweep_amplitude),
        "noise_above": float(np.mean(np.abs(body) > sweep_amplitude)),
        "noise_above_half": float(np.mean(np.abs(body) > 0.5 * sweep_amplitude)),
        "steps": sum(1 for s in auto.steps if s.accepted), "seconds": seconds,
    }


def _row(r: dict) -> str:
    head = f"| {r['shape']} | {r['level']:g} | {r['helmet']} |"
    if r["error"] is not None:
        return head + f" crash: {r['error']} |" + " |" * 9
    harmonics = " ; ".join(f"H{k} {r['true_h'][k]:.1f} / {r['measured_h'][k]:.1f} / {r['model_h'][k]:.1f}" for k in (2, 3))
    named = "yes" if r["named"] else "no (" + ", ".join(r["top"]) + ")"
    limit = "-" if r["drive_limit"] is None else f"{r['drive_limit']:.3g}"
    return (head + f" {named} | {r['identified']:.1f} -> {r['refined']:.2f} | {harmonics} | "
            f"{r['identified_order']} -> {r['order']} / {r['true_order']} | {r['form']} | {limit} | "
            f"{r['noise_peak_db']:.1f}, {100 * r['noise_above']:.2f} %, {100 * r['noise_above_half']:.1f} % | "
            f"{r['steps']} | {r['seconds']:.0f} |")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plants", default="random", choices=("random", "seed"),
                        help="random helmets of the given seeds, or the seed's appendix-A plants (seeds: the sessions')")
    parser.add_argument("--at", default="sweeps", choices=("sweeps", "largest"),
                        help="where a polynomial's level holds: the sweeps' amplitude or the session's largest input")
    parser.add_argument("--seeds", default="11,12")
    parser.add_argument("--paths", default="fb,ff")
    parser.add_argument("--levels", default="-15,-22,-30")
    parser.add_argument("--shapes", default="tanh,poly,hp2,hp20")
    args = parser.parse_args(argv)
    shapes = args.shapes.split(",")
    unknown = sorted(set(shapes) - set(SHAPES))
    if unknown:
        parser.error(f"unknown shape {unknown[0]!r}; known: {', '.join(SHAPES)}")
    print("| shape | H dB | helmet | named | rms/floor identified -> refined | H2, H3 true / sweeps / model (dB) "
          "| order (identified -> refined / true) | refined map | drive limit FS | noise input: peak re sweep (dB), share "
          "above the sweep's amplitude, above half | steps | time (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for shape in shapes:
        for level in (float(x) for x in args.levels.split(",")):
            for seed in (int(x) for x in args.seeds.split(",")):
                for path in args.paths.split(","):
                    helmet = f"{'seed' if args.plants == 'seed' else seed} {path}"
                    t0 = time.perf_counter()
                    try:
                        r = run(seed, path, shape, level, args.plants, args.at)
                    except Exception as error:  # a crash is a result here: reported, and the run goes on
                        r = {"shape": shape, "level": level, "error": f"{type(error).__name__}: {error}".replace("|", "/"),
                             "seconds": time.perf_counter() - t0}
                    r["helmet"] = helmet
                    rows.append(r)
                    print(_row(r), flush=True)
    done = [r for r in rows if r["error"] is None]
    refined = np.array([r["refined"] for r in done] or [np.nan])
    print(f"\n{len(rows)} sessions, {len(rows) - len(done)} crashed: median refined rms/floor {np.median(refined):.2f}, "
          f"worst {np.max(refined):.2f}, <= 1.5x on {int(np.sum(refined <= 1.5))}; named in the top two on "
          f"{sum(r['named'] for r in done)}; order within +-2 of the true on "
          f"{sum(abs(r['order'] - r['true_order']) <= 2 for r in done)}; "
          f"median time {np.median([r['seconds'] for r in rows]):.0f} s")


if __name__ == "__main__":
    main()
