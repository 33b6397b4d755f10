"""Python entry points of firmware generation (used by both command-line front ends).

:func:`generate_firmware` designs, renders, optionally verifies, and writes
``NAME_filter.h``, ``NAME_filter.c`` and ``manifest.json`` into ``outdir`` atomically.
:func:`format_verification_table` prints the verification figures of a manifest.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sysid.core.files import OutputRefused, check_output_directory
from sysid.core.model import Model

from . import __version__, noise
from .errors import CodegenError, OutputError
from .plan import Plan, plan_firmware
from .render import build_context, render_files, validate_name, write_directory
from .verify import verify_host

__all__ = ["MANIFEST_FORMAT", "Manifest", "format_verification_table", "generate_firmware", "load_sweeps"]

MANIFEST_FORMAT = "helmet-anc/firmware-manifest@1"


@dataclass(frozen=True)
class Manifest:
    """The manifest written beside the generated code (``data`` is its JSON content)."""

    outdir: Path
    data: dict

    @property
    def name(self) -> str:
        return self.data["name"]

    @property
    def files(self) -> list[Path]:
        return [self.outdir / f for f in self.data["files"]]

    @property
    def verification(self) -> dict | None:
        return self.data["verification"]


def _complex_list(values) -> list[list[float]]:
    return [[float(np.real(v)), float(np.imag(v))] for v in values]


def _json_ready(value):
    """Nested data with non-finite floats (e.g. the gain of an unstable model) replaced by None."""
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


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
            from sysid.io.recordings import RecordingWarning, load_recording

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


def _manifest_data(plan: Plan, name: str, variant: str, files: dict[str, str], verification) -> dict:
    realisation, cascade = plan.realisation, plan.cascade
    data = {
        "format": MANIFEST_FORMAT,
        "generator": f"helmet-anc codegen {__version__}",
        "name": name,
        "variant": variant,
        "target": plan.target,
        "model": {**plan.provenance, "fs": plan.model.fs, "delay": plan.model.delay,
                  "stable": plan.model.stable, "spectral_radius": plan.model.spectral_radius,
                  "input_nonlinearity": plan.model.input_nonlinearity},
        "board": {"fs": realisation.fs, "delay": realisation.delay, "delay_error_s": realisation.delay_error_s,
                  "resampled_from": realisation.resampled_from,
                  "delay_approximation": ("delay rounded to the nearest board sample" if realisation.resampled_from
                                          else "exact")},
        "realisation": {"form": "balanced", "hankel_singular_values": realisation.hankel_singular_values.tolist(),
                        "order": int(realisation.A.shape[0]), "truncated_from": realisation.truncated_from,
                        "truncation_error_bound": realisation.truncation_bound},
        "cascade": {"scaling": cascade.scaling, "headroom_db": cascade.headroom_db,
                    "realisation_error": cascade.realisation_error,
                    "margins": noise.node_margins(cascade),
                    "sections": [{"order": s.order, "b": list(s.b), "a": list(s.a), "poles": _complex_list(s.poles),
                                  "zeros": _complex_list(s.zeros)} for s in cascade.sections]},
        "formats": {},
        "predicted": {k: v.as_dict() for k, v in plan.predictions.items()},
        "min_snr_db": plan.min_snr_db,
        "verification": verification,
        "files": {filename: hashlib.sha256(text.encode("utf-8")).hexdigest() for filename, text in files.items()},
    }
    data["formats"].update(plan.spec.formats(plan))
    return data


def generate_firmware(model, outdir, name: str | None = None, variant: str = "both", fs: float | None = None,
                      target: str = "generic", min_snr: float = 80.0, allow_unstable: bool = False, sweeps=None,
                      *, order: int | None = None, scaling: str = "linf", headroom_db: float = 6.0,
                      quantiser: str = "efb", force: bool = False, progress=None) -> Manifest:
    """Generate (and with ``sweeps``, verify) the C filter of a model into ``outdir``.

    ``model`` is a :class:`sysid.core.model.Model` or a path to its JSON file; ``name``
    defaults to the model's path ('fb' or 'ff'); ``fs`` is the board rate in Hz
    (None: the model's rate); ``sweeps`` are WAV paths or full-scale arrays whose
    every sample is run through the host build. Raises a CodegenError subclass
    (a ValueError) on bad input, refusal or a failed verification, in which case
    nothing is written. ``outdir`` is checked first: a new folder, or one holding
    only a previous output of ours (proved by its manifest), or any folder with
    ``force``; only files a manifest of ours lists are ever replaced or removed.
    ``progress(done, total, label)``, when given, is called at each stage.
    """
    stages = ["design", "render", *(["verify"] if sweeps else []), "write"]

    def stage(label: str) -> None:
        if progress is not None:
            progress(stages.index(label), len(stages), label)

    try:
        check_output_directory(outdir, "manifest.json", MANIFEST_FORMAT, force=force)
    except OutputRefused as exc:
        raise OutputError(str(exc)) from None
    stage("design")
    model_file = None
    if not isinstance(model, Model):
        model_file = str(model)
        model = Model.load(model)
    name = validate_name(model.path if name is None else name)
    plan = plan_firmware(model, variant=variant, fs=fs, target=target, min_snr=min_snr, allow_unstable=allow_unstable,
                         order=order, scaling=scaling, headroom_db=headroom_db, quantiser=quantiser,
                         model_file=model_file)
    context = build_context(name=name, provenance=plan.provenance, fs=plan.realisation.fs, cascade=plan.cascade,
                            variants=tuple(plan.predictions), fixed=plan.fixed, floating=plan.floating, cmsis=plan.cmsis,
                            target=plan.target)
    stage("render")
    files = render_files(context, target)
    verification = None
    if sweeps:
        stage("verify")
        signals, labels = load_sweeps(sweeps, plan.realisation.fs)
        verification = verify_host(plan, plan.spec.host(name, files, plan), signals, labels)
    data = _json_ready(_manifest_data(plan, name, variant, files, verification))
    manifest_text = json.dumps(data, indent=2, sort_keys=True, allow_nan=False, default=float) + "\n"
    stage("write")
    outdir = write_directory(outdir, {**files, "manifest.json": manifest_text}, force=force)
    if progress is not None:
        progress(len(stages), len(stages), "done")
    return Manifest(outdir=Path(outdir), data=data)


def format_verification_table(manifest: Manifest | dict) -> str:
    """Plain-text table: one row per sweep and variant with LSB/float differences and SNRs."""
    data = manifest.data if isinstance(manifest, Manifest) else manifest
    title = f"{data['name']} ({data['model']['path'].upper()}, {data['target']}, {data['board']['fs']:g} Hz)"
    predicted = data.get("predicted", {})
    verification = data.get("verification")
    lines = [title]
    header = f"{'sweep':<24} {'variant':<7} {'samples':>8} {'vs reference':>16} {'SNR vs float64':>15} {'predicted':>10}"
    lines.append(header)
    lines.append("-" * len(header))
    if not verification:
        for variant, figures in predicted.items():
            lines.append(f"{'(not verified)':<24} {variant:<7} {'':>8} {'':>16} {'':>15} {figures['snr_db']:>8.1f}dB")
        return "\n".join(lines)
    for row in verification["sweeps"]:
        for variant in ("q15", "float"):
            if variant not in row:
                continue
            figures = row[variant]
            if "max_lsb_difference" in figures:
                agreement = f"{figures['max_lsb_difference']} LSB"
            else:
                agreement = "bit-exact" if figures["bit_exact"] else f"{figures['max_relative_difference']:.2g}"
            snr = figures["snr_vs_float64_db"]
            snr_text = "exact" if snr is None else f"{snr:.1f}dB"
            lines.append(f"{row['sweep'][:24]:<24} {variant:<7} {row['samples']:>8} {agreement:>16} "
                         f"{snr_text:>15} {predicted[variant]['snr_db']:>8.1f}dB")
    return "\n".join(lines)
