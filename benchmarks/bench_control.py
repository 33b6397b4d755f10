"""Control benchmark: per plant pair, the limits, our design judged on the true plants, FxLMS, orders, cost.

For each pair of ``tests/control_cases`` (the seed's appendix-A pair, then random FB/FF pairs of the
project's generator), identify both paths on short synthetic sessions, record the road noise with
ANC off (``recording_with_anc_off``), design on the identified models with that recording at the
board's latency (``anc.design``, as ``helmet-anc design --disturbance`` does) and judge the controller
on the TRUE plants against a fresh noise realisation (``control_cases.judge``). Printed per pair as a
Markdown row, means over the third-octave bands 50 Hz-1 kHz (dB, positive = quieter at the ear): the
bounds the controller records (causal feed-forward, coherence, robust feedback), ours judged (ff, fb,
both), FxLMS converged (normalised, 128 taps, the identified S as its secondary-path model, step from
its stability bound, the record doubled until it converges, up to ``--fxlms-longest`` seconds,
``anc.fxlms.run_until_converged``) with the time to reach it, the filters' orders
and the design's CPU time, and the estimate ``anc.design.board_cost`` of the control path's instructions per
sample (S, Q and W at ``sysid.core.board``'s per-section figures).

With ``--emulate`` each pair's controller is also generated (``generate-firmware --controller``, min SNR 30 dB)
and its control path (``firmware/anc_control.c``, per-sample path, latency 2) counted on the emulated Cortex-M4
(QEMU mps2-an386, ``codegen.qemu_cost``) by ``benchmarks/bench_board_controller.py``'s ``instruction_counts``:
the Q15 path's instructions per sample beside the estimate (and its share of the 1750 of the control budget,
half of a 168 MHz M4 at 48 kHz), each filter's one-sample step and sections, the float32 path's count, and
whether the ear words of the Python twin, the host build and the M4 ELF on QEMU are equal in the closed loop on
the pair's true FB plant (``closed_loop_equal``, ``--loop-seconds`` of the default wind/engine noise; 0 leaves
it out). A variant whose predicted SNR misses the 30 dB floor is "not generated: <reason>" (what
``generate-firmware`` notes) and is then counted all the same, generated without the floor.

    python benchmarks/bench_control.py [--pairs seed,3,11] [--fxlms-seconds S] [--fxlms-longest S] [--fxlms-only]
                                       [--no-fxlms] [--emulate] [--loop-seconds S]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# This checkout's packages, not an installed copy, and the tests' control cases.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from control_cases import (JUDGED, RANDOM_FB_SEEDS, identified, judge, random_pair,  # noqa: E402
                           recording_with_anc_off, road_noise, seed_pair)

from anc import design  # noqa: E402
from anc.controller import BOARD_LATENCY_SAMPLES  # noqa: E402
from anc.design import BOARD_CYCLES_PER_SAMPLE, board_cost  # noqa: E402
from anc.disturbance import from_recording  # noqa: E402
from anc.fxlms import run_until_converged  # noqa: E402
from codegen.controller import CONTROLLER_MIN_SNR_DB as MIN_SNR  # noqa: E402
from codegen.qemu_cost import have_m4_tools  # noqa: E402
from sysid.core.errors import HelmetAncError  # noqa: E402

EMULATED_COLUMNS = ("S order", "Q15 path emulated instr. / sample (% of budget)", "emulated S / Q / W step (sections)",
                    "float32 path emulated", "host = twin = QEMU (Q15, float32)")


def _mean(values) -> float:
    chosen = [v for v, j in zip(values or [], JUDGED) if j and v is not None]
    return float(np.mean(chosen)) if chosen else float("nan")


def _fxlms_text(fx) -> str:
    """FxLMS's converged attenuation, the time to reach it and its record, the step against its bound."""
    return (f"{fx.attenuation_db:.1f} dB ({fx.seconds:.1f} s of {fx.run_seconds:.0f} s" if fx.converged else
            f"not converged in {fx.run_seconds:.0f} s ({fx.attenuation_db:.1f} dB at the end") + \
        f", {fx.mu:.2g} / {fx.mu_bound:.2g})"


def _refusals(controller) -> dict[str, str]:
    """Why each variant is not generated at ``generate-firmware --controller``'s default SNR floor (none: it is)."""
    from codegen.controller import plan_controller
    from codegen.errors import PrecisionError

    try:
        return dict(plan_controller(controller, min_snr=MIN_SNR).refused)
    except PrecisionError:  # neither variant kept: ask each alone for its reason
        reasons = {}
        for key in ("q15", "float"):
            try:
                plan_controller(controller, variant=key, min_snr=MIN_SNR)
            except PrecisionError as exc:
                reasons[key] = str(exc)
        return reasons


def _emulated(controller, pair, loop_seconds: float) -> list[str]:
    """The emulated columns of one pair (``EMULATED_COLUMNS``): its controller generated and counted on QEMU. A
    variant refused at ``MIN_SNR`` is said so and still counted, generated without the floor: its instructions do
    not depend on its round-off."""
    from bench_board_controller import closed_loop_equal, instruction_counts

    from codegen.api import generate_controller_firmware
    from codegen.controller import plan_controller

    refused = _refusals(controller)
    floor = -math.inf if refused else MIN_SNR
    with tempfile.TemporaryDirectory(prefix="bench_control.") as tmp:
        root = Path(tmp)
        fw = root / "fw_control"
        generate_controller_firmware(controller, fw, min_snr=floor)
        plan = plan_controller(controller, min_snr=floor)
        costs = instruction_counts(plan, fw, root)
        loops = closed_loop_equal(plan, fw, root, loop_seconds, pair.s, pair.p) if loop_seconds > 0 else {}

    def count(key: str, share: bool) -> str:
        path = costs[key]["control path"]
        text = f"{path:.0f}" + (f" ({100 * path / BOARD_CYCLES_PER_SAMPLE:.1f} %)" if share else "")
        return f"not generated: {refused[key]}; emulated without the floor: {text}" if key in refused else text

    q15 = costs["q15"]
    sections = {name: len(plan.plans[part].cascade.sections) if part in plan.plans else 0
                for name, part in (("ctl_s", "model"), ("ctl_q", "fb"), ("ctl_w", "ff"))}
    steps = " / ".join(f"{q15[name]:.0f} ({sections[name]})" for name in sections)
    equal = ", ".join(("yes" if v["host_equals_twin"] and v["m4_equals_host"] else
                       f"NO (host = twin {v['host_equals_twin']}, QEMU = host {v['m4_equals_host']})")
                      + f" ({v['frames']} frames)" for v in loops.values()) or "not run"
    return [str(controller.internal_model.order), count("q15", True), steps, count("float", False), equal]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--pairs", default=",".join(["seed", *map(str, RANDOM_FB_SEEDS)]),
                        help="comma-separated: seed and random FB seeds")
    parser.add_argument("--fxlms-seconds", type=float, default=8.0, help="the first noise record (s)")
    parser.add_argument("--fxlms-longest", type=float, default=512.0, help="the longest record tried (s)")
    parser.add_argument("--fxlms-only", action="store_true", help="FxLMS alone, at the board's latency")
    parser.add_argument("--no-fxlms", action="store_true", help="leave FxLMS out (its column '-')")
    parser.add_argument("--emulate", action="store_true",
                        help="generate each controller and count its control path on the emulated Cortex-M4 (QEMU)")
    parser.add_argument("--loop-seconds", type=float, default=0.3,
                        help="with --emulate: the closed loop comparing twin, host and QEMU (s; 0: not run)")
    args = parser.parse_args()
    if args.emulate and have_m4_tools():
        print(f"--emulate skipped: {have_m4_tools()} not found; the emulated columns are left out", file=sys.stderr)
        args.emulate = False
    wall, cpu = time.perf_counter(), time.process_time()
    if args.fxlms_only:
        print("| pair | FxLMS converged (time of record, step / bound) |\n|---|---|")
    else:
        extra = EMULATED_COLUMNS if args.emulate else ()
        print("| pair | causal ff bound | within the rules | coherence bound | robust fb bound | ours ff | ours fb | "
              "ours both | worst band vs predicted | quietest band | FxLMS converged (time, step / bound) | "
              "W order (of) | Q order (of) | design CPU s | board instructions per sample (estimate) |"
              + "".join(f" {c} |" for c in extra))
        print("|---" * (15 + len(extra)) + "|")
    for key in args.pairs.split(","):
        name = "seed" if key == "seed" else f"random {int(key)}"
        pair = seed_pair() if key == "seed" else random_pair(int(key))
        s_id, p_id = identified(name)
        if args.fxlms_only:
            _, fx = run_until_converged(pair.s, s_id, lambda s, p=pair.p: road_noise(p, s, 5), args.fxlms_seconds,
                                        args.fxlms_longest, BOARD_LATENCY_SAMPLES, 128)
            print(f"| {pair.name} | {_fxlms_text(fx)} |")
            continue
        disturbance = from_recording(recording_with_anc_off(pair.p), s_id.fs, ff_model=p_id)
        started = time.process_time()
        try:
            controller = design(s_id, p_id, disturbance)
        except HelmetAncError as exc:
            print(f"| {pair.name} | refused: {exc} ||||||||||| ")
            continue
        seconds = time.process_time() - started
        judged = judge(controller, pair)
        if args.no_fxlms:
            fx_text = "-"
        else:
            _, fx = run_until_converged(pair.s, s_id, lambda s, p=pair.p: road_noise(p, s, 5), args.fxlms_seconds,
                                        args.fxlms_longest, controller.latency_samples, 128)
            fx_text = _fxlms_text(fx)
        emulated = _emulated(controller, pair, args.loop_seconds) if args.emulate else []
        limits = controller.limits or {}
        t = controller.provenance.get("truncation", {})
        orders = [f"{t[k]['order']} ({t[k]['full_order']})" if k in t else "-" for k in ("ff", "fb")]
        predicted = controller.predicted_attenuation_db
        worst = max(float(np.max(np.abs(judged.per_band[p] - np.array(predicted[p]))[JUDGED])) for p in judged.per_band)
        quietest = min(float(np.min(judged.per_band[p][JUDGED])) for p in judged.per_band)
        print(f"| {pair.name} | {_mean(limits.get('causal_ff_db')):.1f} | "
              f"{_mean(limits.get('causal_ff_ruled_db')):.1f} | {_mean(limits.get('coherence_db')):.1f} | "
              f"{_mean(limits.get('feedback_db')):.1f} | "
              + " | ".join(f"{judged.mean(p):.1f}" if p in judged.per_band else "-" for p in ("ff", "fb", "both"))
              + f" | {worst:.1f} | {quietest:.1f} | {fx_text} | {orders[0]} | {orders[1]} | {seconds:.0f} | "
              f"{board_cost(s_id.order, *(f.order for f in (controller.fb, controller.ff) if f is not None))} |"
              + "".join(f" {c} |" for c in emulated))
        sys.stdout.flush()
    print(f"\ntotal: {time.perf_counter() - wall:.0f} s wall, {time.process_time() - cpu:.0f} s CPU")


if __name__ == "__main__":
    main()
