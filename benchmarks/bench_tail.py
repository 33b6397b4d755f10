"""Benchmark of the reverberant tail: diagnose and refine --auto on measured responses capped below their states.

As the issue's user meets it: a session through a measured response (``sysid.simulate.measured_session``: a
headphone transfer function, HD 600 on a KEMAR, and a dummy-head HRIR, FABIAN; credits in sysid/core/data),
23 s of noise and two 8 s sweeps, and a model capped below the states the response needs (the frequency-limited
truncation of the session's least-squares FIR at the cap, the cap in its provenance). Per response: the tail
finding (length, states), diagnose's and refine --auto's CPU and wall time with the cap lifted (target: refine
--auto <= 60 s on 2 cores), the validation error before and after, and the order reached. Prints Markdown.

    python benchmarks/bench_tail.py [--short]
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

from sysid.core.model import MAX_ORDER
from sysid.diagnose import diagnose
from sysid.refine import refine_auto

# The capped models are the reverberant-tail test's (tests/tail_cases.py).
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from tail_cases import CAPPED, capped_session  # noqa: E402

THESIS = dict(noise_duration=23.0, sweep_duration=8.0, sweep_silence=0.5)
SHORT = dict(noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)


def timed(function):
    c0, t0 = time.process_time(), time.perf_counter()
    result = function()
    return result, time.process_time() - c0, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--short", action="store_true", help="the tests' 8 s sessions instead of 23 s")
    args = parser.parse_args()
    spec = SHORT if args.short else THESIS
    print(f"Machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}. "
          f"Session: {spec['noise_duration']:g} s noise, two {spec['sweep_duration']:g} s sweeps.\n")
    print("| response | cap | before (x floor) | tail length (ms) | states needed | diagnose CPU / wall (s) | "
          "refine --auto CPU / wall (s) | after (x floor) | order |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in CAPPED:
        session, model = capped_session(name, **spec)
        findings, d_cpu, d_wall = timed(lambda: diagnose(model, session.noise, session.sweeps))
        tail = next(f for f in findings if f.effect == "reverberant-tail")
        auto, r_cpu, r_wall = timed(lambda: refine_auto(model, session.noise, session.sweeps, max_order=MAX_ORDER))
        print(f"| {name} | {model.order} | {findings.comparison.ratio:.2f} | {tail.params.get('length_ms', 0):.1f} | "
              f"{tail.params.get('states')} | {d_cpu:.1f} / {d_wall:.1f} | {r_cpu:.1f} / {r_wall:.1f} | "
              f"{auto.after.ratio:.2f} | {auto.model.order} |")


if __name__ == "__main__":
    main()
