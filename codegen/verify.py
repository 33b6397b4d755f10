"""Verification of a host build against the Python references, sample by sample.

For every sweep: the Q15 C output must equal :func:`codegen.reference.fixed_reference`
to 0 LSB; the float C output must equal :func:`codegen.reference.float32_reference`
within ``FLOAT_TOLERANCE`` (it is bit-exact when the compiler keeps the operation
order, which the build flags ask for); both are compared with the float64 model
as an SNR. Each sweep is fed in two blocks of unequal length, so the state is
carried over between calls as on the board.
"""

from __future__ import annotations

import numpy as np

from .build import HostFilter
from .cmsis import q31_to_q15
from .errors import VerificationError
from .plan import Plan
from .reference import float64_reference
from .targets import CMSIS_FLOAT_TOLERANCE, FLOAT_TOLERANCE

__all__ = ["CMSIS_FLOAT_TOLERANCE", "FLOAT_TOLERANCE", "CmsisPackageFilter", "reference_outputs", "snr_db", "verify_host"]



def snr_db(reference: np.ndarray, test: np.ndarray) -> float:
    """10 log10(sum reference^2 / sum (test - reference)^2), in dB."""
    reference = np.asarray(reference, float)
    error = np.asarray(test, float) - reference
    noise = float(np.sum(error**2))
    return float("inf") if noise == 0 else float(10 * np.log10(np.sum(reference**2) / noise))


def _blocks(run, x: np.ndarray) -> np.ndarray:
    cut = max(1, (x.size * 3) // 7)
    return np.concatenate((run(x[:cut]), run(x[cut:])))


def reference_outputs(plan: Plan, u: np.ndarray) -> dict:
    """Python references of every planned variant for the full-scale input u.

    Per variant key: ``<key>_input`` (the samples the C takes), ``<key>`` (the
    reference output) and ``float64_<key>`` (the realised model on the same input).
    """
    out = {}
    for variant in plan.variants:
        x = variant.to_input(u)
        out[f"{variant.key}_input"] = x
        out[variant.key] = variant.reference(plan.design(variant.key), x)
        out[f"float64_{variant.key}"] = float64_reference(plan.realisation, np.asarray(variant.to_float(x), float),
                                                          plan.model.input_nonlinearity)
    return out


def _compare(variant, label: str, c_out: np.ndarray, reference: np.ndarray, exact: np.ndarray) -> dict:
    """Figures of one variant's C output against its reference; raises on a mismatch."""
    if variant.exact:
        diff = np.abs(c_out.astype(np.int64) - reference.astype(np.int64))
        figures = {"max_lsb_difference": int(diff.max(initial=0)), "mismatches": int(np.count_nonzero(diff)),
                   "snr_vs_float64_db": snr_db(exact, variant.to_float(c_out))}
        if diff.any():
            raise VerificationError(f"{label}: {variant.key.upper()} C output differs from the bit-exact reference in "
                                    f"{figures['mismatches']} samples (max {figures['max_lsb_difference']} LSB)")
        return figures
    scale = max(1.0, float(np.max(np.abs(reference), initial=0.0)))
    diff = float(np.max(np.abs(c_out.astype(float) - reference.astype(float)), initial=0.0)) / scale
    figures = {"max_relative_difference": diff, "bit_exact": bool(np.array_equal(c_out, reference)),
               "snr_vs_float64_db": snr_db(exact, variant.to_float(c_out))}
    if not diff <= variant.tolerance:
        raise VerificationError(f"{label}: {variant.key} C output differs from the float32 reference by {diff:.3g} "
                                f"(tolerance {variant.tolerance:g})")
    return figures


def verify_host(plan: Plan, host: HostFilter, sweeps: list[np.ndarray], names: list[str] | None = None) -> dict:
    """Run each sweep through the C code and the references; raise on any mismatch.

    Returns {"sweeps": [...per-sweep figures...], "passed": True}.
    """
    names = names or [f"sweep {i + 1}" for i in range(len(sweeps))]
    rows = []
    for label, u in zip(names, sweeps):
        refs = reference_outputs(plan, np.asarray(u, float))
        row = {"sweep": label, "samples": int(np.size(u))}
        for variant in plan.variants:
            host.reset(variant.kind)
            c_out = _blocks(getattr(host, f"process_{variant.kind}"), refs[f"{variant.key}_input"])
            row[variant.key] = _compare(variant, label, c_out, refs[variant.key], refs[f"float64_{variant.key}"])
        rows.append(row)
    return {"sweeps": rows, "passed": True}


class CmsisPackageFilter:
    """The ``cmsisdsp`` package's kernels run on the cmsis target's tables, as the C would on the board.

    Used to verify ``--target cmsis``, whose C needs CMSIS-DSP headers that the host
    build does not have; the delay and Q15 conversions are applied as in the template.
    """

    def __init__(self, tables):
        try:
            import cmsisdsp
        except ImportError:
            raise VerificationError("--verify with --target cmsis needs the cmsisdsp package (pip install cmsisdsp)") from None
        self._dsp, self._tables = cmsisdsp, tables
        self.reset("q15")
        self.reset("f32")

    def reset(self, kind: str) -> None:
        dsp, tables, stages = self._dsp, self._tables, len(self._tables.q31_coefficients)
        if kind == "q15":
            q31_rows = np.array(tables.q31_coefficients, np.int32).ravel()
            if tables.kernel == "q15":
                self._fixed = dsp.arm_biquad_casd_df1_inst_q15()
                rows = np.array([(r[0], 0, *r[1:]) for r in tables.q15_coefficients], np.int16).ravel()
                dsp.arm_biquad_cascade_df1_init_q15(self._fixed, stages, rows, np.zeros(4 * stages, np.int16),
                                                    tables.q15_post_shift)
            elif tables.kernel == "q31":
                self._fixed = dsp.arm_biquad_casd_df1_inst_q31()
                dsp.arm_biquad_cascade_df1_init_q31(self._fixed, stages, q31_rows, np.zeros(4 * stages, np.int32),
                                                    tables.post_shift)
            else:
                self._fixed = dsp.arm_biquad_cas_df1_32x64_ins_q31()
                dsp.arm_biquad_cas_df1_32x64_init_q31(self._fixed, stages, q31_rows, np.zeros(4 * stages, np.int64),
                                                      tables.post_shift)
            self._line_q15 = np.zeros(tables.delay, np.int16)
        else:
            self._f32 = dsp.arm_biquad_cascade_df2T_instance_f32()
            dsp.arm_biquad_cascade_df2T_init_f32(self._f32, stages, np.array(tables.f32_coefficients, np.float32).ravel(),
                                                 np.zeros(2 * stages, np.float32))
            self._line_f32 = np.zeros(tables.delay, np.float32)

    @staticmethod
    def _delay(line: np.ndarray, x: np.ndarray):
        joined = np.concatenate((line, x))
        return joined[: x.size], joined[x.size:]

    def process_q15(self, x: np.ndarray) -> np.ndarray:
        u, self._line_q15 = self._delay(self._line_q15, np.asarray(x, np.int16))
        if self._tables.kernel == "q15":
            return np.asarray(self._dsp.arm_biquad_cascade_df1_q15(self._fixed, u), np.int16)
        run = (self._dsp.arm_biquad_cascade_df1_q31 if self._tables.kernel == "q31"
               else self._dsp.arm_biquad_cas_df1_32x64_q31)
        return q31_to_q15(run(self._fixed, u.astype(np.int32) * 65536), self._tables.output_shift)

    def process_f32(self, x: np.ndarray) -> np.ndarray:
        u, self._line_f32 = self._delay(self._line_f32, np.asarray(x, np.float32))
        return np.asarray(self._dsp.arm_biquad_cascade_df2T_f32(self._f32, u), np.float32)
