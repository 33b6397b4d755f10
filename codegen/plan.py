"""The complete firmware design of one model: every number the generated code needs.

:func:`plan_firmware` runs realisation -> sections -> variant designs -> noise
predictions and applies the refusals of the design reference: an unstable model
(unless allowed) and any variant whose predicted SNR misses the requested one.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace

from sysid.model import Model

from . import noise
from .cmsis import KERNEL_FUNCTIONS, KERNELS, CmsisTables, design_cmsis
from .errors import CodegenError, PrecisionError
from .fixedpoint import QUANTISERS, FixedDesign, design_fixed
from .float32 import FloatDesign, design_float32
from .realise import Realisation, realise
from .sections import Cascade, design_cascade

__all__ = ["TARGETS", "VARIANTS", "Plan", "model_hash", "plan_firmware"]

VARIANTS = ("float", "q15", "both")
TARGETS = ("generic", "cmsis")


def model_hash(model: Model) -> str:
    """sha256 (hex) of the model's canonical JSON, which names it in generated files."""
    return hashlib.sha256(model.to_json().encode("utf-8")).hexdigest()


@dataclass
class Plan:
    """Designs and predictions of the variants to generate (``None`` when not requested)."""

    model: Model
    model_file: str | None
    realisation: Realisation
    cascade: Cascade
    target: str
    fixed: FixedDesign | None
    floating: FloatDesign | None
    cmsis: CmsisTables | None
    predictions: dict = field(default_factory=dict)
    min_snr_db: float = 80.0
    kernel_predictions: dict = field(default_factory=dict)

    @property
    def provenance(self) -> dict:
        ident = self.model.identification or {}
        return {"path": self.model.path, "file": self.model_file, "hash": model_hash(self.model),
                "gamma": ident.get("gamma"), "order": self.model.order}


def _reason(variant: str, prediction: noise.Prediction, min_snr: float) -> str:
    cause = ("coefficient quantisation" if prediction.coefficient_snr_db < prediction.roundoff_snr_db
             else "round-off noise (output quantiser and section round-off)")
    return (f"{variant} variant refused: predicted SNR {prediction.snr_db:.1f} dB is below --min-snr {min_snr:g} dB; "
            f"limited by {cause} (coefficients {prediction.coefficient_snr_db:.1f} dB, "
            f"round-off {prediction.roundoff_snr_db:.1f} dB)")


def plan_firmware(model: Model, *, variant: str = "both", fs: float | None = None, target: str = "generic",
                  min_snr: float = 80.0, allow_unstable: bool = False, order: int | None = None,
                  scaling: str = "linf", headroom_db: float = 6.0, quantiser: str = "efb",
                  model_file: str | None = None) -> Plan:
    """Design everything for ``generate_firmware``; raises a CodegenError subclass on refusal."""
    if variant not in VARIANTS:
        raise CodegenError(f"--variant must be one of {', '.join(VARIANTS)}; found {variant!r}")
    if target not in TARGETS:
        raise CodegenError(f"--target must be one of {', '.join(TARGETS)}; found {target!r}")
    if quantiser not in QUANTISERS:
        raise CodegenError(f"quantiser must be one of {', '.join(QUANTISERS)}; found {quantiser!r}")
    realisation = realise(model, fs=fs, order=order, allow_unstable=allow_unstable)
    if target == "cmsis":
        # CMSIS-DSP's Q31 kernels wrap on overflow: only worst-case (l1) scaling makes that impossible.
        scaling = "l1"
    cascade = design_cascade(realisation, scaling=scaling, headroom_db=headroom_db)
    if quantiser == "round" and target == "generic" and variant != "float" and any(s.poles for s in cascade.sections):
        # Rounding to nearest inside a recursive section is a nonlinearity that can sustain a zero-input
        # limit cycle (Oppenheim & Schafer, Discrete-Time Signal Processing, zero-input limit cycles); floor with first-order
        # error feedback has no such cycle (the residue fed back makes the state decay to exactly 0).
        raise PrecisionError("--quantiser round refused: rounding in a recursive section leaves a zero-input limit "
                             "cycle (a constant hum of a few LSB); use --quantiser efb (the default)")
    polynomial = model.input_nonlinearity
    want_fixed, want_float = variant in ("q15", "both"), variant in ("float", "both")
    fixed = floating = cmsis = None
    predictions, kernel_predictions = {}, {}
    if target == "cmsis":
        cmsis = design_cmsis(cascade, realisation.delay, polynomial)
        if want_fixed:
            # The cheapest CMSIS kernel whose predicted SNR meets the request.
            for kernel in KERNELS:
                kernel_predictions[kernel] = noise.predict_cmsis(cascade, replace(cmsis, kernel=kernel), realisation.fs)
            good = [k for k in KERNELS if kernel_predictions[k].snr_db >= min_snr]
            if not good:
                best = max(KERNELS, key=lambda k: kernel_predictions[k].snr_db)
                raise PrecisionError(_reason(f"q15 variant (best CMSIS kernel {KERNEL_FUNCTIONS[best]})",
                                             kernel_predictions[best], min_snr).replace(" variant refused", " refused", 1))
            cmsis = replace(cmsis, kernel=good[0])
            predictions["q15"] = kernel_predictions[good[0]]
        if want_float:
            predictions["float"] = noise.predict_cmsis_f32(cascade, cmsis, realisation.fs)
    else:
        if want_fixed:
            fixed = design_fixed(cascade, realisation.delay, polynomial, quantiser)
            predictions["q15"] = noise.predict_fixed(cascade, fixed, realisation.fs)
        if want_float:
            floating = design_float32(cascade, realisation.delay, polynomial)
            predictions["float"] = noise.predict_float32(cascade, floating, realisation.fs)
    for name, prediction in predictions.items():
        if prediction.snr_db < min_snr:
            raise PrecisionError(_reason(name, prediction, min_snr))
    return Plan(model=model, model_file=model_file, realisation=realisation, cascade=cascade, target=target,
                fixed=fixed, floating=floating, cmsis=cmsis, predictions=predictions, min_snr_db=float(min_snr),
                kernel_predictions=kernel_predictions)
