"""Verification of a host build against the Python references, sample by sample.

Fifth step of firmware generation (plan -> context -> render -> build -> verify ->
manifest): it takes the plan, a filter running on the host (:mod:`codegen.build`) and
the sweeps (:func:`load_sweeps`, the one place firmware generation reads recordings),
and returns the figures the manifest records.

For every sweep: the Q15 C output must equal :func:`codegen.reference.fixed_reference`
to 0 LSB; the float C output must equal :func:`codegen.reference.float32_reference`
within ``FLOAT_TOLERANCE`` (it is bit-exact when the compiler keeps the operation
order, which the build flags ask for); both are compared with the float64 model
as an SNR. Each sweep is fed in two blocks of unequal length, so the state is
carried over between calls as on the board.

The SNR on a sweep (its output power over its error against the float64 model on the
same input) is a different quantity from the plan's predicted SNR, which is referred to
a full-scale output sine (``codegen.noise``): a sweep's output is quieter, and a
fixed-point variant's round-off noise is absolute. ``sweep_prediction`` predicts the
quantity measured for the fixed-point variants: their round-off noise at that sweep's
output power with the coefficient error at its worst frequency of the band (appendix-A FF,
Q15: 84.8 dB predicted, 85.5 measured, 98.1 against a full-scale sine). A float32
variant's round-off is relative to each node's signal and has no such prediction.
``format_verification_table`` prints them side by side, each saying what it is against.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from sysid.io.recordings import RecordingWarning, load_recording

from .build import HostFilter
from .errors import CodegenError, VerificationError
from .plan import Plan
from .reference import float64_reference
from .targets import CMSIS_FLOAT_TOLERANCE, FLOAT_TOLERANCE

__all__ = ["CMSIS_FLOAT_TOLERANCE", "FLOAT_TOLERANCE", "load_sweeps", "reference_outputs", "snr_db", "sweep_prediction",
           "verify_host", "format_verification_table"]


def load_sweeps(sweeps, fs: float | None = None) -> tuple[list[np.ndarray], list[str]]:
    """Sweep inputs (full-scale float64) and labels from WAV paths, recordings or arrays.

    A path is read with :func:`sysid.io.recordings.load_recording`; of a recording
    (a path's or a :class:`sysid.io.recordings.Recording` given directly) the input
    channel ``u`` is what the filter sees on the board. With ``fs`` given, a
    recording at another sample rate is an error (the filter runs at ``fs``;
    nothing is resampled).
    """
    signals, labels = [], []
    for index, sweep in enumerate(sweeps or []):
        if isinstance(sweep, (str, os.PathLike)):
            with warnings.catch_warnings():
                # Quality warnings concern the ear channel, which the filter never sees.
                warnings.simplefilter("ignore", RecordingWarning)
                sweep = load_recording(sweep)
        if hasattr(sweep, "u") and hasattr(sweep, "fs"):
            label = Path(str(getattr(sweep, "path", f"sweep {index + 1}"))).name
            if fs is not None and abs(sweep.fs - fs) > 1e-9 * fs:
                raise CodegenError(f"{label}: recorded at {sweep.fs:g} Hz but the filter runs at {fs:g} Hz")
            signals.append(np.asarray(sweep.u, float))
            labels.append(label)
        else:
            array = np.asarray(sweep, float).reshape(-1)
            if array.size == 0 or not np.all(np.isfinite(array)):
                raise CodegenError(f"sweep {index + 1} must be a non-empty array of finite samples")
            signals.append(array)
            labels.append(f"sweep {index + 1}")
    return signals, labels


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


def sweep_prediction(prediction, exact: np.ndarray) -> float:
    """Predicted SNR (dB) on one sweep against the float64 model, for a fixed-point variant: its output
    ``exact`` (FS) and the variant's ``codegen.noise.Prediction``, whose round-off power P_r (FS^2) is
    absolute, the same at any level: 1/snr = P_r / P_out + 1/snr_c (snr_c: the coefficient error at its worst
    frequency in band). A float32 variant's round-off is relative to the signal at each node, which a sweep
    spreads differently over the band than a full-scale sine: no prediction on the sweep is made for it
    (measured: appendix-A FB 107 dB against 113 dB full-scale)."""
    power = float(np.mean(np.square(exact))) if np.size(exact) else 0.0
    if power <= 0:
        return float("-inf")
    coefficient = 10 ** (-prediction.coefficient_snr_db / 10) if np.isfinite(prediction.coefficient_snr_db) else 0.0
    total = prediction.roundoff_power / power + coefficient
    return float("inf") if total == 0 else float(-10 * np.log10(total))


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
            exact = refs[f"float64_{variant.key}"]
            row[variant.key] = _compare(variant, label, c_out, refs[variant.key], exact)
            if variant.exact:
                row[variant.key]["predicted_snr_db"] = sweep_prediction(plan.predictions[variant.key], exact)
        rows.append(row)
    return {"sweeps": rows, "passed": True}


def _db_text(value) -> str:
    return "exact" if value is None or value == float("inf") else f"{value:.1f} dB"


def format_verification_table(data: dict) -> str:
    """Plain-text table of a manifest's data: one row per sweep and variant with the agreement with the
    reference, the SNR measured on the sweep and predicted for it (both against the float64 model on the
    same input), and the plan's SNR against a full-scale output sine (what ``--min-snr`` judges)."""
    title = f"{data['name']} ({data['model']['path'].upper()}, {data['target']}, {data['board']['fs']:g} Hz)"
    predicted = data.get("predicted", {})
    verification = data.get("verification")
    columns = (("sweep", 24, "<"), ("variant", 7, "<"), ("samples", 8, ">"), ("vs reference", 13, ">"),
               ("SNR on sweep", 13, ">"), ("predicted", 10, ">"), ("full-scale sine", 16, ">"))

    def row(*cells):
        return " ".join(f"{str(c)[:w]:{a}{w}}" for c, (_, w, a) in zip(cells, columns))

    header = row(*(name for name, _, _ in columns))
    lines = [title, header, "-" * len(header)]
    if not verification:
        for variant, figures in predicted.items():
            lines.append(row("(not verified)", variant, "", "", "", "", _db_text(figures["snr_db"])))
    else:
        for sweep in verification["sweeps"]:
            for variant in ("q15", "float"):
                if variant not in sweep:
                    continue
                figures = sweep[variant]
                if "max_lsb_difference" in figures:
                    agreement = f"{figures['max_lsb_difference']} LSB"
                else:
                    agreement = "bit-exact" if figures["bit_exact"] else f"{figures['max_relative_difference']:.2g}"
                on_sweep = _db_text(figures["predicted_snr_db"]) if "predicted_snr_db" in figures else "-"
                lines.append(row(sweep["sweep"], variant, sweep["samples"], agreement,
                                 _db_text(figures["snr_vs_float64_db"]), on_sweep, _db_text(predicted[variant]["snr_db"])))
    if verification:
        lines.append("SNR on sweep: its output power over its error against the float64 model on the same input; "
                     "predicted for the fixed-point")
        lines.append("  variants (absolute round-off at the sweep's level, coefficient error at its worst frequency); "
                     "float32's round-off is relative")
    lines.append("full-scale sine: the predicted SNR against a full-scale output sine, which --min-snr judges (float32: "
                 "at the band's worst")
    lines.append("  frequency for the loudest sine the filter takes there, its relative round-off following the signal)")
    return "\n".join(lines)
