"""Board control loop: latency, attenuation (host C, QEMU Cortex-M4, Python twin, float64
design) and the per-sample cost of the control path on the emulated Cortex-M4.

The controller is designed by ``anc.design`` on the seed (Appendix A) plants for the
per-sample path's latency (2 samples) and run on the true FB plant with the default
wind/engine disturbance. Instruction counts come from a QEMU execution trace
(``codegen.qemu_cost``): a driver calls the codec interrupt handler
``anc_control_dma_done`` (and, separately, each filter on one sample per call: ``step``
for Q15, ``process`` for float32, as the per-sample path calls them) for
two numbers of frames; the difference of the counts over the difference of the frames is
the cost per sample, call overhead included (the handler is called once per frame).

    python benchmarks/bench_control_loop.py [--seconds 2.9] [--write BENCHMARKS.md]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from anc import DesignOptions, design  # noqa: E402
from anc.closed_loop import measured_attenuation, run_closed_loop  # noqa: E402
from anc.controller import Controller  # noqa: E402
from anc.disturbance import default_disturbance, synthesize  # noqa: E402
from anc.prediction import band_centres  # noqa: E402
from codegen.api import generate_controller_firmware  # noqa: E402
from codegen.control_loop import board_loop  # noqa: E402
from codegen.controller import plan_controller  # noqa: E402
from codegen.qemu_cost import M4_CFLAGS, build_m4_elf, count_regions, per_sample_cost, per_sample_function_cost
from codegen.reference import to_q15  # noqa: E402
from sysid.core.plants import appendix_a_model  # noqa: E402

FIRMWARE = ROOT / "firmware"
BUDGET_CYCLES = 3500  # 168 MHz / 48 kHz
SHORT, LONG = 16, 272

# Driver of the instruction counts: regions between cost_mark calls (codegen.qemu_cost).
DRIVER = """
#include "anc_control.h"
#include "cost_mark.h"
static anc_control ctl;
static anc_value in[1], out[1];
static void frames(unsigned n)
{
    unsigned k;
    for (k = 0; k < n; ++k) {
        unsigned h = (k / ANC_CONTROL_BLOCK) & 1u, slot = k % ANC_CONTROL_BLOCK;
        ctl.ear[h][slot] = (int16_t)((k * 2654435761u) >> 20);
        ctl.chin[h][slot] = (int16_t)((k * 40503u) >> 4);
        if (slot + 1u == ANC_CONTROL_BLOCK) {
            anc_control_dma_done(&ctl, h);
        }
    }
}
#define FILTER_RUN(filter, state_type)                    \\
    static void run_##filter(unsigned n)                  \\
    {                                                     \\
        static state_type st;                             \\
        unsigned k;                                       \\
        for (k = 0; k < n; ++k) {                         \\
            in[0] = (anc_value)((k * 2654435761u) >> 28); \\
            PROCESS(filter, &st, in, out, 1u);            \\
        }                                                 \\
    }
#ifdef ANC_CONTROL_F32
#define PROCESS(filter, s, i, o, n) filter##_f32_process(s, i, o, n)
FILTER_RUN(ctl_s, ctl_s_f32_state)
FILTER_RUN(ctl_q, ctl_q_f32_state)
FILTER_RUN(ctl_w, ctl_w_f32_state)
#else
/* The per-sample path's call: step (one sample, no block bookkeeping). */
#define PROCESS(filter, s, i, o, n) ((o)[0] = filter##_q15_step(s, (i)[0]))
FILTER_RUN(ctl_s, ctl_s_q15_state)
FILTER_RUN(ctl_q, ctl_q_q15_state)
FILTER_RUN(ctl_w, ctl_w_q15_state)
#endif
int main(void)
{
    anc_control_init(&ctl);
    cost_mark(); frames(SHORT);
    cost_mark(); frames(LONG);
    cost_mark(); run_ctl_s(SHORT);
    cost_mark(); run_ctl_s(LONG);
    cost_mark(); run_ctl_q(SHORT);
    cost_mark(); run_ctl_q(LONG);
    cost_mark(); run_ctl_w(SHORT);
    cost_mark(); run_ctl_w(LONG);
    cost_mark();
    return 0;
}
"""


def _plant_file(work: Path, plant, d, chin) -> None:
    work.mkdir(parents=True, exist_ok=True)
    header = np.concatenate(([plant.order, plant.delay], np.ravel(plant.A), np.ravel(plant.B), np.ravel(plant.C),
                             np.ravel(plant.D)))
    header.astype(np.float64).tofile(work / "plant.f64")
    np.asarray(d, np.float64).tofile(work / "d.f64")
    np.asarray(chin, np.int16).tofile(work / "chin.q15")


def _make(target: str, work: Path, **variables) -> None:
    args = ["make", "-s", "-f", str(FIRMWARE / "Makefile"), target] + [f"{k}={v}" for k, v in variables.items()]
    subprocess.run(args, cwd=work, check=True, capture_output=True, timeout=600)


def closed_loops(root: Path, seconds: float) -> dict:
    s_true, p_true = appendix_a_model("fb"), appendix_a_model("ff")
    started = time.process_time()
    controller = design(s_true, p_true, options=DesignOptions(latency=2))
    design_s = time.process_time() - started
    generate_controller_firmware(controller, root / "ctl")
    # The same filters with the latency of 4-frame blocks, for the cost of the block variant only.
    data = controller.to_dict()
    data["latency_samples"] = 8
    generate_controller_firmware(Controller.from_dict(data), root / "ctl8")
    plan = plan_controller(controller)
    fs = controller.fs
    x, u = synthesize(default_disturbance(fs, p_true), int(seconds * fs), fs, 0)
    d = p_true.simulate(x) + u
    chin = to_q15(x)
    centres = np.array(band_centres())
    checked = (centres >= 50.0) & (centres <= 1000.0)

    def summary(ear):
        att = np.array(measured_attenuation(d, ear, fs))
        return {"mean_50_1k": float(np.mean(att[checked])), "max_50_1k": float(np.max(att[checked])),
                "bands": att}

    rows = {"float64 design (anc.closed_loop)": summary(run_closed_loop(controller, s_true, d, x).e)}
    equal = {}
    for variant, flag in (("q15", ""), ("float", "-DANC_CONTROL_F32")):
        started = time.process_time()
        twin = board_loop(plan, s_true, d, chin, variant)
        twin_s = time.process_time() - started
        rows[f"{variant}: Python twin"] = summary(twin.ear / 32768.0)
        runs = {}
        for where, target in (("host", "closed-loop-host"), ("m4", "closed-loop-m4")):
            work = root / f"{variant}_{where}"
            _plant_file(work, s_true, d, chin)
            _make(target, work, CTL=root / "ctl", CONTROL=flag)
            exe = ([str(work / "build" / "closed_loop_host")] if where == "host" else
                   ["qemu-system-arm", "-M", "mps2-an386", "-nographic", "-monitor", "none", "-serial", "none",
                    "-semihosting-config", "enable=on,target=native", "-kernel", str(work / "build" / "closed_loop_m4.elf")])
            subprocess.run(exe, cwd=work, check=True, capture_output=True, timeout=600)
            runs[where] = np.fromfile(work / "ear.q15", np.int16)
            label = "host C (gcc)" if where == "host" else "Cortex-M4 ELF (QEMU)"
            rows[f"{variant}: {label}"] = summary(runs[where] / 32768.0)
        equal[variant] = {"host_equals_twin": bool(np.array_equal(runs["host"], twin.ear)),
                          "m4_equals_host": bool(np.array_equal(runs["m4"], runs["host"])),
                          "twin_cpu_s": twin_s}
    return {"controller": controller, "plan": plan, "rows": rows, "equal": equal, "design_s": design_s,
            "samples": d.size, "fs": fs}


def instruction_counts(root: Path) -> dict:
    result = {}
    for variant, flags in (("q15", ()), ("float", ("-DANC_CONTROL_F32",))):
        for block, folder in ((1, "ctl"), (4, "ctl8")):
            work = root / f"cost_{variant}_{block}"
            work.mkdir(parents=True, exist_ok=True)
            (work / "driver.c").write_text(DRIVER.replace("SHORT", str(SHORT)).replace("LONG", str(LONG)))
            sources = [work / "driver.c", FIRMWARE / "anc_control.c", *sorted((root / folder).glob("ctl_*_filter.c"))]
            elf = build_m4_elf(sources, work, include_dirs=(root / folder,),
                               cflags=(*M4_CFLAGS, *flags, f"-DANC_CONTROL_BLOCK={block}u"))
            counts = count_regions(elf, functions=("anc_control_dma_done",))
            if block == 1:
                names = ["control path, per sample (latency 2)", "ctl_s (internal model), one sample per call",
                         "ctl_q (Q), one sample per call", "ctl_w (W), one sample per call"]
                result.setdefault(variant, {}).update(
                    {name: per_sample_cost(counts, SHORT, LONG, first=2 * i) for i, name in enumerate(names)})
                # The handler's own instructions (d_hat, delay lines, drive sum, limiter), filters excluded.
                result[variant]["anc_control_dma_done itself (d_hat, delays, limiter)"] = per_sample_function_cost(
                    counts, "anc_control_dma_done", SHORT, LONG)
            else:
                result[variant]["control path, blocks of 4 frames (latency 8)"] = per_sample_cost(counts, SHORT, LONG)
    return result


def render(loops: dict, costs: dict, seconds: float) -> str:
    plan = loops["plan"]
    sections = {part: len(p.cascade.sections) for part, p in plan.plans.items()}
    orders = {part: int(p.realisation.A.shape[0]) for part, p in plan.plans.items()}
    lines = [
        "## Board control loop",
        "",
        "`python benchmarks/bench_control_loop.py` (machine: 2 cores, 24 GiB, shared with other jobs; "
        "2026-11-23). Controller designed by `anc.design` on the seed (Appendix A) plants for a latency of "
        f"2 samples ({loops['design_s']:.1f} s CPU), generated by `generate-firmware --controller`, run by "
        "`firmware/anc_control.c` (per-sample path, `ANC_CONTROL_BLOCK` = 1) against the true FB plant with the "
        f"default wind/engine disturbance, {seconds:g} s at {loops['fs']:g} Hz ({loops['samples']} frames).",
        "",
        "Latency: the codec DMA's two halves of one frame make the processing latency 2 samples "
        "(capture at k, compute during k + 1, play at k + 2; `ANC_PROCESSING_LATENCY` = 2 x block); the converter "
        "latency (`ANC_CONVERTER_LATENCY_SAMPLES`, the codec's filter group delay) and the acoustics are inside the "
        "identified S. Blocks of 4 frames would make it 8 samples.",
        "",
        f"Filters: internal model S order {orders['model']} ({sections['model']} sections), "
        f"Q order {orders['fb']} ({sections['fb']} sections), W order {orders['ff']} ({sections['ff']} sections).",
        "",
        "Attenuation (dB, 10 log10 of ear power without / with control, third-octave bands, 0.25 s start-up "
        "skipped), mean and best over the bands 50 Hz-1 kHz:",
        "",
        "| run | mean 50 Hz-1 kHz | best band |",
        "|---|---|---|",
    ]
    for label, row in loops["rows"].items():
        lines.append(f"| {label} | {row['mean_50_1k']:.2f} | {row['max_50_1k']:.2f} |")
    lines += ["", "Ear words of the runs: " + "; ".join(
        f"{v}: host C {'equals' if e['host_equals_twin'] else 'DIFFERS FROM'} the Python twin, QEMU "
        f"{'equals' if e['m4_equals_host'] else 'DIFFERS FROM'} the host (twin {e['twin_cpu_s']:.1f} s CPU)"
        for v, e in loops["equal"].items()) + ".", ""]
    lines += ["Instructions per sample on the emulated Cortex-M4 (QEMU trace, `codegen.qemu_cost`; "
              f"{LONG - SHORT} frames; `arm-none-eabi-gcc -O2`), against the budget of {BUDGET_CYCLES} cycles "
              "per sample (168 MHz, 48 kHz). Instructions are not cycles: loads take 2 cycles and taken branches "
              "2-4 on a Cortex-M4, so the cycle count is higher than these figures. The filters' rows call each "
              "filter as the per-sample path does: `NAME_q15_step` (Q15), `NAME_f32_process` on one sample "
              "(float32).", "",
              "| per sample | Q15 | float32 |", "|---|---|---|"]
    for name in costs["q15"]:
        q, f = costs["q15"][name], costs["float"][name]
        lines.append(f"| {name} | {q:.0f} ({100 * q / BUDGET_CYCLES:.1f} %) | {f:.0f} ({100 * f / BUDGET_CYCLES:.1f} %) |")
    lines.append("")
    return "\n".join(lines)


def write_section(path: Path, section: str) -> None:
    text = path.read_text(encoding="utf-8") if path.exists() else ""
    start = text.find("## Board control loop")
    if start < 0:
        text = text.rstrip("\n") + "\n\n" + section
    else:
        end = text.find("\n## ", start + 1)
        # One blank line between this section and the next heading.
        text = text[:start] + section.rstrip("\n") + "\n" + ("\n" + text[end + 1:] if end >= 0 else "")
    path.write_text(text, encoding="utf-8")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.9, help="closed-loop length (at most 131072 frames)")
    parser.add_argument("--write", type=Path, help="replace the 'Board control loop' section of this Markdown file")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_control_loop.") as tmp:
        root = Path(tmp)
        loops = closed_loops(root, args.seconds)
        costs = instruction_counts(root)
    section = render(loops, costs, args.seconds)
    print(section)
    if args.write:
        write_section(args.write, section)
    return 0


if __name__ == "__main__":
    sys.exit(main())
