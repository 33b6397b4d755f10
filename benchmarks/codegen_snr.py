"""Firmware generation benchmark, SNR: the generated code and CMSIS-DSP's kernels against the float64 model.

Part of ``benchmarks/bench_codegen.py``: on two sweeps (exponential and linear,
20 Hz-4 kHz, scaled so the float64 output peaks at -1 dBFS), the SNR of the generated
Q15 and float32 code (host build through cffi), of CMSIS-DSP's kernels from the
``cmsisdsp`` package on the same sections (plain Q31 DF1, 32x64 Q31 DF1, float32 DF2T)
and on scipy's ``zpk2sos`` sections, and the bound set by rounding the float64 output
itself to Q15.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.signal

from codegen.api import generate_firmware
from codegen.build import build_host
from codegen.cmsis import design_cmsis
from codegen.plan import plan_firmware
from codegen.reference import float64_reference, from_q15, to_q15
from codegen.sections import Cascade, Section
from codegen.verify import snr_db
from sysid.core import lti
from sysid.core.plants import appendix_a_model

__all__ = ["measure_snr", "naive_tables", "sweeps"]


def sweeps(model, seconds: float, peak_dbfs: float = -1.0) -> list[np.ndarray]:
    t = np.arange(int(seconds * model.fs)) / model.fs
    out = []
    for method in ("logarithmic", "linear"):
        s = scipy.signal.chirp(t, 20.0, t[-1], 4000.0, method=method)
        out.append(s * min(1.0, 10 ** (peak_dbfs / 20) / np.max(np.abs(model.simulate(s)))))
    return out


def _cmsis_runs(tables, q: np.ndarray, xf: np.ndarray) -> dict:
    # cmsisdsp is optional: only this benchmark and the cmsis target's verification need it.
    import cmsisdsp as dsp

    stages = len(tables.q31_coefficients)
    coefficients = np.array(tables.q31_coefficients, np.int32).ravel()
    x31 = q.astype(np.int32) * 65536
    plain = dsp.arm_biquad_casd_df1_inst_q31()
    dsp.arm_biquad_cascade_df1_init_q31(plain, stages, coefficients, np.zeros(4 * stages, np.int32), tables.post_shift)
    wide = dsp.arm_biquad_cas_df1_32x64_ins_q31()
    dsp.arm_biquad_cas_df1_32x64_init_q31(wide, stages, coefficients, np.zeros(4 * stages, np.int64), tables.post_shift)
    df2t = dsp.arm_biquad_cascade_df2T_instance_f32()
    dsp.arm_biquad_cascade_df2T_init_f32(df2t, stages, np.array(tables.f32_coefficients, np.float32).ravel(),
                                         np.zeros(2 * stages, np.float32))
    # The Q31 tables' last stage is scaled by 2^-output_shift so no stage can wrap; scale back here.
    scale = 2.0 ** (tables.output_shift - 31)
    return {"q31": dsp.arm_biquad_cascade_df1_q31(plain, x31).astype(float) * scale,
            "q31_32x64": dsp.arm_biquad_cas_df1_32x64_q31(wide, x31).astype(float) * scale,
            "f32_df2t": np.asarray(dsp.arm_biquad_cascade_df2T_f32(df2t, xf), float)}


def naive_tables(model):
    """CMSIS tables from scipy's zpk2sos (its pairing and order, no per-section scaling, gain in section 1).

    zpk2sos pads the missing zeros at the origin, which advances the output by
    r = (poles - zeros) samples; the returned r lets the comparison undo that.
    """
    zeros, poles = model.zeros(), model.poles()
    sos = scipy.signal.zpk2sos(zeros, poles, 1.0)
    advance = poles.size - zeros.size
    w = np.linspace(0.001, np.pi, 4096)
    _, shape = scipy.signal.sosfreqz(sos, worN=w)
    shape = shape * np.exp(-1j * w * advance)
    target = lti.frequency_response(model.A, model.B, model.C, model.D, np.exp(1j * w))
    sos[0, :3] *= float(np.real(np.vdot(shape, target) / np.vdot(shape, shape)))
    sections = tuple(Section(b=tuple(r[:3]), a=tuple(r[3:]), poles=(), zeros=()) for r in sos)
    cascade = Cascade(sections=sections, scaling="none", headroom_db=0.0, node_gains=(), realisation_error=0.0)
    return design_cmsis(cascade, 0), advance


def measure_snr(path: str, seconds: float, workdir: Path) -> list[dict]:
    model = appendix_a_model(path)
    plan = plan_firmware(model, min_snr=0.0)
    manifest = generate_firmware(model, workdir / f"{path}_snr", min_snr=0.0)
    host = build_host(path, (manifest.outdir / f"{path}_filter.h").read_text(),
                      (manifest.outdir / f"{path}_filter.c").read_text())
    # The tables --target cmsis generates (l1-scaled cascade, anti-wrap output shift).
    tables = plan_firmware(model, target="cmsis", min_snr=0.0).cmsis
    naive, advance = naive_tables(model)
    rows = []
    for label, u in zip(("exponential", "linear"), sweeps(model, seconds)):
        q = to_q15(u)
        xf = from_q15(q).astype(np.float32)
        exact = float64_reference(plan.realisation, from_q15(q))
        host.reset("q15")
        host.reset("f32")
        cm = _cmsis_runs(tables, q, xf)
        nv = _cmsis_runs(naive, q, xf)
        late = slice(advance, None)
        early = slice(None, q.size - advance)
        rows.append({
            "sweep": label,
            "fixed": snr_db(exact, from_q15(host.process_q15(q))),
            "float": snr_db(exact, host.process_f32(xf)),
            "q15_bound": snr_db(exact, from_q15(to_q15(exact))),
            "cmsis_q31": snr_db(exact, cm["q31"]),
            "cmsis_q31_q15": snr_db(exact, from_q15(to_q15(cm["q31"]))),
            "cmsis_32x64": snr_db(exact, cm["q31_32x64"]),
            "cmsis_df2t": snr_db(exact, cm["f32_df2t"]),
            "naive_q31": snr_db(exact[late], nv["q31"][early]),
            "naive_df2t": snr_db(exact[late], nv["f32_df2t"][early]),
        })
    return rows
