"""A designed controller at the board's orders on the board: each filter's sections, predicted and measured
SNR per variant, the host C = Python twin = emulated Cortex-M4 closed loop, and the control path's cost.

The controller is the seed pair's (``tests/control_cases``: both paths identified on short sessions,
the road noise recorded with ANC off, latency 2, the design fitted to the board by default), or the
one given with ``--controller``. Per filter S, Q, W and variant: the section form, the predicted SNR
against a full-scale output sine (``codegen.noise``, what --min-snr judges) and the SNR measured
against the float64 realisation on two sweeps 20 Hz-4 kHz (exponential, linear) whose float64 output
peaks at -1 dBFS, run through the generated C built for the host (``codegen.verify.verify_host``, which
also checks the C against the Python twin: 0 LSB for Q15, bit for bit for float32), beside the Q15 variant's
prediction on that sweep (its absolute round-off at the sweep's output power, ``codegen.verify.sweep_prediction``:
a filter whose gain spans tens of dB over 20 Hz-4 kHz gives a sweep far quieter than a full-scale sine). The closed loop
(``firmware/closed_loop.c`` with ``anc_control.c``, per-sample path, on the seed's true FB plant with
the default wind/engine noise) compares the ear words of the Python twin, the host build and the
Cortex-M4 ELF on QEMU. The control path's instructions per sample on the emulated Cortex-M4 are
counted by ``benchmarks/bench_control_loop.py``'s driver (``codegen.qemu_cost``), against the 1750
cycles of the control budget (half of a 168 MHz Cortex-M4 at 48 kHz).

    python benchmarks/bench_board_controller.py [--controller controller.json] [--seconds 0.3]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.signal

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_control_loop import DRIVER, FIRMWARE, LONG, SHORT, _make, _plant_file  # noqa: E402

from anc.controller import Controller  # noqa: E402
from anc.disturbance import default_disturbance, synthesize  # noqa: E402
from codegen.api import generate_controller_firmware  # noqa: E402
from codegen.build import host_filter  # noqa: E402
from codegen.context import build_context  # noqa: E402
from codegen.control_loop import board_loop  # noqa: E402
from codegen.controller import FILTER_NAMES, plan_controller  # noqa: E402
from codegen.qemu_cost import M4_CFLAGS, build_m4_elf, count_regions, per_sample_cost  # noqa: E402
from codegen.reference import to_q15  # noqa: E402
from codegen.render import render_files  # noqa: E402
from codegen.verify import verify_host  # noqa: E402
from sysid.core.board import BOARD_CYCLES_PER_SAMPLE  # noqa: E402
from sysid.core.plants import appendix_a_model  # noqa: E402

BUDGET = BOARD_CYCLES_PER_SAMPLE / 2
FORMS = {"q15": "Q31 direct form I, 64-bit accumulator, error feedback",
         "float": "two poles: balanced state space, A - I; others around z = 1"}


def seed_pair_controller() -> Controller:
    """The seed pair's controller as the tests design it (identified models, recording with ANC off)."""
    from control_cases import identified, recording_with_anc_off, seed_pair

    from anc.design import design
    from anc.disturbance import from_recording

    s_model, p_model = identified("seed")
    return design(s_model, p_model, from_recording(recording_with_anc_off(seed_pair().p), ff_model=p_model))


def _sweeps(model, seconds: float) -> list[np.ndarray]:
    t = np.arange(int(seconds * model.fs)) / model.fs
    out = []
    for method in ("logarithmic", "linear"):
        s = scipy.signal.chirp(t, 20.0, t[-1], 4000.0, method=method)
        out.append(s * min(1.0, 10 ** (-1.0 / 20) / np.max(np.abs(model.simulate(s)))))
    return out


def filter_rows(plan, seconds: float) -> list[dict]:
    """Per filter: order, sections, and per variant the form, predicted and measured SNR (dB)."""
    rows = []
    for part, sub in plan.plans.items():
        name = FILTER_NAMES[part]
        files = render_files(build_context(name=name, provenance=sub.provenance, fs=sub.realisation.fs,
                                           cascade=sub.cascade, variants=tuple(sub.predictions), fixed=sub.fixed,
                                           floating=sub.floating))
        verification = verify_host(sub, host_filter("cffi", name, files, sub.designs), _sweeps(sub.model, seconds),
                                   ["exponential", "linear"])
        row = {"filter": name, "order": int(sub.realisation.A.shape[0]), "sections": len(sub.cascade.sections),
               "closest_pole": float(min((1 - abs(p) for s in sub.cascade.sections for p in s.poles), default=1.0))}
        for key, prediction in sub.predictions.items():
            measured = [sweep[key]["snr_vs_float64_db"] for sweep in verification["sweeps"]]
            on_sweep = [sweep[key].get("predicted_snr_db") for sweep in verification["sweeps"]]
            row[key] = {"form": FORMS[key], "predicted": prediction.snr_db, "coefficients": prediction.coefficient_snr_db,
                        "roundoff": prediction.roundoff_snr_db, "measured": measured, "on_sweep": on_sweep}
        rows.append(row)
    return rows


def closed_loop_equal(plan, fw: Path, root: Path, seconds: float, s_true=None, p_true=None) -> dict:
    """Ear words of the Python twin, the host build and the Cortex-M4 ELF (QEMU) per variant: equal? The loop
    runs on the true FB plant ``s_true`` with the default wind/engine noise through ``p_true`` (the seed's
    appendix-A pair when not given)."""
    s_true = appendix_a_model("fb") if s_true is None else s_true
    p_true = appendix_a_model("ff") if p_true is None else p_true
    fs = plan.controller.fs
    x, u = synthesize(default_disturbance(fs, p_true), int(seconds * fs), fs, 0)
    d = p_true.simulate(x) + u
    chin = to_q15(x)
    result = {}
    for variant, flag in (("q15", ""), ("float", "-DANC_CONTROL_F32")):
        if variant not in plan.variants:
            continue
        started = time.process_time()
        twin = board_loop(plan, s_true, d, chin, variant)
        runs = {}
        for where, target in (("host", "closed-loop-host"), ("m4", "closed-loop-m4")):
            work = root / f"{variant}_{where}"
            _plant_file(work, s_true, d, chin)
            _make(target, work, CTL=fw, CONTROL=flag)
            import subprocess

            exe = ([str(work / "build" / "closed_loop_host")] if where == "host" else
                   ["qemu-system-arm", "-M", "mps2-an386", "-nographic", "-monitor", "none", "-serial", "none",
                    "-semihosting-config", "enable=on,target=native", "-kernel",
                    str(work / "build" / "closed_loop_m4.elf")])
            subprocess.run(exe, cwd=work, check=True, capture_output=True, timeout=1200)
            runs[where] = np.fromfile(work / "ear.q15", np.int16)
        result[variant] = {"frames": int(d.size), "host_equals_twin": bool(np.array_equal(runs["host"], twin.ear)),
                           "m4_equals_host": bool(np.array_equal(runs["m4"], runs["host"])),
                           "twin_cpu_s": time.process_time() - started}
    return result


def instruction_counts(plan, fw: Path, root: Path) -> dict:
    """Emulated Cortex-M4 instructions per sample: the control path (per-sample, latency 2) and each filter."""
    result = {}
    for variant, flags in (("q15", ()), ("float", ("-DANC_CONTROL_F32",))):
        if variant not in plan.variants:
            continue
        work = root / f"cost_{variant}"
        work.mkdir(parents=True, exist_ok=True)
        (work / "driver.c").write_text(DRIVER.replace("SHORT", str(SHORT)).replace("LONG", str(LONG)))
        sources = [work / "driver.c", FIRMWARE / "anc_control.c", *sorted(fw.glob("ctl_*_filter.c"))]
        elf = build_m4_elf(sources, work, include_dirs=(fw,), cflags=(*M4_CFLAGS, *flags, "-DANC_CONTROL_BLOCK=1u"))
        counts = count_regions(elf, functions=("anc_control_dma_done",))
        names = ["control path", "ctl_s", "ctl_q", "ctl_w"]
        result[variant] = {name: per_sample_cost(counts, SHORT, LONG, first=2 * i) for i, name in enumerate(names)}
    return result


def render(rows: list[dict], loops: dict, costs: dict, plan) -> str:
    lines = ["| filter | order (sections) | closest pole 1 - abs(p) | variant: form | predicted SNR (coefficients, "
             "round-off) | measured SNR, exponential / linear sweep (predicted on the sweep) | M4 instructions / "
             "sample, one-sample call |",
             "|---|---|---|---|---|---|---|"]
    for row in rows:
        for key in plan.variants:
            v = row[key]
            # A fixed-point variant's round-off is absolute: on a sweep quieter than a full-scale sine its SNR is
            # lower by the sweep's level (codegen.verify.sweep_prediction); float32's follows the signal.
            on_sweep = "" if None in v["on_sweep"] else f" ({v['on_sweep'][0]:.1f} / {v['on_sweep'][1]:.1f})"
            lines.append(f"| {row['filter']} | {row['order']} ({row['sections']}) | {row['closest_pole']:.1e} | "
                         f"{key}: {v['form']} | {v['predicted']:.1f} ({v['coefficients']:.1f}, {v['roundoff']:.1f}) | "
                         f"{v['measured'][0]:.1f} / {v['measured'][1]:.1f}{on_sweep} | {costs[key][row['filter']]:.0f} |")
    for key in plan.variants:
        path = costs[key]["control path"]
        loop = loops.get(key, {})
        lines.append(f"| control path | | | {key} | | closed loop ({loop.get('frames', 0)} frames): host = twin "
                     f"{loop.get('host_equals_twin')}, QEMU = host {loop.get('m4_equals_host')} | "
                     f"**{path:.0f}** of {BUDGET:.0f} ({100 * path / BUDGET:.0f} %) |")
    for key, reason in plan.refused.items():
        lines.append(f"\n{key} not generated: {reason}")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controller", type=Path, help="controller JSON (default: the seed pair's, designed here)")
    parser.add_argument("--seconds", type=float, default=0.3, help="closed-loop length (s)")
    parser.add_argument("--sweep-seconds", type=float, default=2.0, help="length of each sweep (s)")
    parser.add_argument("--min-snr", type=float, default=30.0)
    args = parser.parse_args(argv)
    started = time.process_time()
    controller = Controller.load(args.controller) if args.controller else seed_pair_controller()
    design_s = time.process_time() - started
    with tempfile.TemporaryDirectory(prefix="bench_board_controller.") as tmp:
        root = Path(tmp)
        fw = root / "fw_control"
        generate_controller_firmware(controller, fw, min_snr=args.min_snr)
        plan = plan_controller(controller, min_snr=args.min_snr)
        rows = filter_rows(plan, args.sweep_seconds)
        costs = instruction_counts(plan, fw, root)
        loops = closed_loop_equal(plan, fw, root, args.seconds)
    print(f"controller: {args.controller or 'seed pair (designed, ' + format(design_s, '.1f') + ' CPU s)'}; "
          f"variants {', '.join(plan.variants)}")
    print(render(rows, loops, costs, plan))
    return 0


if __name__ == "__main__":
    sys.exit(main())
