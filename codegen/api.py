"""Python entry points of firmware generation (used by both command-line front ends).

The one module that joins the steps (plan -> context -> render -> build -> verify ->
manifest; each imports only those before it):
:func:`generate_firmware` designs, renders, optionally verifies, and writes
``NAME_filter.h``, ``NAME_filter.c`` and ``manifest.json`` into ``outdir`` atomically;
:func:`generate_controller_firmware` does the same for a controller's filters
(:mod:`codegen.controller`) and its ``controller_config.h``.
:func:`format_verification_table` prints the verification figures of a manifest.
"""

from __future__ import annotations

from pathlib import Path

from sysid.core.model import Model

from .build import host_filter
from .c_syntax import validate_name
from .context import build_context, controller_config_context
from .controller import CONTROL_BLOCK_MAX, CONTROLLER_MIN_SNR_DB, FILTER_NAMES, plan_controller
from .manifest import (MANIFEST_FORMAT, Manifest, check_output, json_ready, manifest_data, manifest_text,
                       write_directory)
from .plan import plan_firmware
from .render import render_files, render_template
from .verify import format_verification_table as _verification_table
from .verify import load_sweeps, verify_host

__all__ = ["MANIFEST_FORMAT", "Manifest", "format_verification_table", "generate_controller_firmware",
           "generate_firmware", "load_sweeps"]


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

    check_output(outdir, force)
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
        verification = verify_host(plan, host_filter(plan.spec.host, name, files, plan.designs), signals, labels)
    data = json_ready(manifest_data(name, files, verification, variant=variant, **plan.record()))
    stage("write")
    outdir = write_directory(outdir, {**files, "manifest.json": manifest_text(data)}, force=force)
    if progress is not None:
        progress(len(stages), len(stages), "done")
    return Manifest(outdir=Path(outdir), data=data)


def generate_controller_firmware(controller, outdir, *, variant: str = "both",
                                 min_snr: float = CONTROLLER_MIN_SNR_DB,
                                 quantiser: str = "efb", force: bool = False, progress=None) -> Manifest:
    """Generate the control path's filters of ``controller`` (an :class:`anc.controller.Controller`
    or a path to its JSON) into ``outdir`` (:func:`codegen.controller.plan_controller`); returns the
    :class:`codegen.manifest.Manifest`. The output-folder rules are those of ``generate_firmware``.
    A requested variant that misses ``min_snr`` in any filter is left out of every filter; the
    manifest's ``variants`` lists those generated and ``refused`` each left out with its reason."""
    check_output(outdir, force)
    if progress is not None:
        progress(0, 3, "design")
    plan = plan_controller(controller, variant=variant, min_snr=min_snr, quantiser=quantiser)
    controller_hash = plan.controller_hash()
    if progress is not None:
        progress(1, 3, "render")
    files: dict[str, str] = {}
    filters = {}
    for part, sub in plan.plans.items():
        name = FILTER_NAMES[part]
        context = build_context(name=name, provenance=plan.provenance(part, controller_hash), fs=sub.realisation.fs,
                                cascade=sub.cascade, variants=tuple(sub.predictions), fixed=sub.fixed,
                                floating=sub.floating)
        rendered = render_files(context)
        files.update(rendered)
        filters[name] = manifest_data(name, rendered, None, variant=variant, **sub.record())
    files["controller_config.h"] = render_template("controller_config.h.j2",
                                                   controller_config_context(plan, controller_hash))
    data = manifest_data("controller", files, None, kind="controller",
                         controller={"file": plan.controller_file, "sha256": controller_hash, "fs": plan.controller.fs,
                                     "latency_samples": plan.latency_samples,
                                     # The control path's processing latency is 2 x ANC_CONTROL_BLOCK
                                     # (firmware/anc_control.h).
                                     "largest_control_block": min(CONTROL_BLOCK_MAX, plan.latency_samples // 2)},
                         filters=filters, headroom=plan.headroom, variants=plan.variants, refused=plan.refused)
    data = json_ready(data)
    if progress is not None:
        progress(2, 3, "write")
    outdir = write_directory(outdir, {**files, "manifest.json": manifest_text(data)}, force=force)
    if progress is not None:
        progress(3, 3, "done")
    return Manifest(outdir=Path(outdir), data=data)


def format_verification_table(manifest: Manifest | dict) -> str:
    """``codegen.verify.format_verification_table`` of a manifest (or its data)."""
    return _verification_table(manifest.data if isinstance(manifest, Manifest) else manifest)
