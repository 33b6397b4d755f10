"""Control benchmark: per plant, attenuation designed on identified models and run on the true plants.

For each helmet (the seed's appendix-A pair, then random pairs: FB path of seed n, FF path
of the next seed at the same rate), identify both paths on short synthetic sessions, design
on the identified models and on the true models, run both on the true plants
(``anc.closed_loop.verify``) and the FxLMS adaptation (identified S as its secondary-path
model), and print a Markdown table: mean attenuation over 50 Hz - 1 kHz (dB) per
configuration, ours vs the true-plant design vs FxLMS converged, and design time (CPU s).
The true-plant design is made like for like: the same design settings and the uncertainty
band the design under test was given (the identified FB model's, ``anc.uncertainty.model_uncertainty``);
the former comparison (the true models with their own, default 20 % band) is printed beside it.

    python benchmarks/bench_control.py [--random N] [--seconds S]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from conftest import FAST_OPTIONS, SHORT  # noqa: E402

from anc import design  # noqa: E402
from anc.closed_loop import verify  # noqa: E402
from anc.disturbance import default_disturbance, synthesize  # noqa: E402
from anc.fxlms import convergence, run_fxlms  # noqa: E402
from anc.prediction import band_centres  # noqa: E402
from anc.uncertainty import model_uncertainty  # noqa: E402
from sysid.core.errors import HelmetAncError  # noqa: E402
from sysid.identify import identify  # noqa: E402
from sysid.random_plant import random_plant, random_session  # noqa: E402
from sysid.simulate import SessionSpec, simulate_session  # noqa: E402

CENTRES = np.array(band_centres())
CHECKED = (CENTRES >= 50.0) & (CENTRES <= 1000.0)


def _sessions(args):
    yield "seed appendix A", simulate_session(SessionSpec(path="fb", seed=11, **SHORT)), \
        simulate_session(SessionSpec(path="ff", seed=11, **SHORT))
    for seed in range(1, args.random + 1):
        other = seed + 1000
        while random_plant(other, "ff").fs != random_plant(seed, "fb").fs:
            other += 1
        yield f"random {seed}/{other}", random_session(seed, "fb", **SHORT), random_session(other, "ff", **SHORT)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--random", type=int, default=4)
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--fxlms-seconds", type=float, default=4.0)
    args = parser.parse_args()
    wall, cpu = time.perf_counter(), time.process_time()
    print("| helmet | part | predicted | ours achieved | true-plant design (same band) | true-plant design (default band, before) "
          "| FxLMS converged (time) | worst band error | stable | design CPU s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, s_session, p_session in _sessions(args):
        s_id = identify(s_session.noise, s_session.sweeps, "fb", FAST_OPTIONS).model
        p_id = identify(p_session.noise, p_session.sweeps, "ff", FAST_OPTIONS).model
        s_true, p_true = s_session.plant, p_session.plant
        disturbance = default_disturbance(s_id.fs, p_id)
        started = time.process_time()
        try:
            ours = design(s_id, p_id, disturbance)
        except HelmetAncError as exc:
            print(f"| {name} | - | refused: {exc} | | | | | | | |")
            continue
        seconds = time.process_time() - started
        limit = design(s_true, p_true, default_disturbance(s_true.fs, p_true), uncertainty=model_uncertainty(s_id))
        before = design(s_true, p_true, default_disturbance(s_true.fs, p_true))
        results = verify(ours, limit, s_true, p_true, disturbance, seconds=args.seconds)
        former = verify(ours, before, s_true, p_true, disturbance, seconds=args.seconds)
        x, u = synthesize(disturbance, int(args.fxlms_seconds * s_true.fs), s_true.fs, 5)
        run = run_fxlms(s_true, s_id, x, p_true.simulate(x) + u)
        fx_db, fx_time = convergence(run, s_true.fs)
        for r, b in zip(results, former):
            fx = f"{fx_db:.1f} dB ({fx_time:.1f} s)" if r.part == "ff" else ""
            worst = np.max(np.abs(r.achieved - r.predicted)[CHECKED])
            print(f"| {name} | {r.part} | {np.mean(r.predicted[CHECKED]):.1f} | {np.mean(r.achieved[CHECKED]):.1f} | "
                  f"{np.mean(r.limit[CHECKED]):.1f} | {np.mean(b.limit[CHECKED]):.1f} | {fx} | {worst:.2f} | {r.stable} | "
                  f"{seconds:.2f} |")
        sys.stdout.flush()
    print(f"\ntotal: {time.perf_counter() - wall:.0f} s wall, {time.process_time() - cpu:.0f} s CPU")


if __name__ == "__main__":
    main()
