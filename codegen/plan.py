"""The complete firmware design of one model: every number the generated code needs.

:func:`plan_firmware` runs realisation -> sections -> the designs of the requested
variants of the target (:mod:`codegen.targets`) -> noise predictions, and applies the
refusals of the design reference: an unstable model (unless allowed) and any variant
whose predicted SNR misses the requested one.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

from sysid.core.model import Model

from .cmsis import CmsisTables
from .errors import CodegenError, PrecisionError
from .fixedpoint import QUANTISERS, FixedDesign
from .float32 import FloatDesign
from .realise import Realisation, realise
from .sections import Cascade, design_cascade
from .targets import TARGETS as _REGISTRY
from .targets import VARIANTS, DesignInputs, Target, get_target, refusal_reason

__all__ = ["TARGETS", "VARIANTS", "Plan", "model_hash", "plan_firmware"]

TARGETS = tuple(_REGISTRY)


def model_hash(model: Model) -> str:
    """sha256 (hex) of the model's canonical JSON, which names it in generated files."""
    return hashlib.sha256(model.to_json().encode("utf-8")).hexdigest()


@dataclass
class Plan:
    """Designs and predictions of the variants to generate.

    ``designs`` maps each variant's plan field ('fixed', 'floating', 'cmsis') to its
    design; the attributes of those names give them (``None`` when not requested).
    """

    model: Model
    model_file: str | None
    realisation: Realisation
    cascade: Cascade
    target: str
    designs: dict = field(default_factory=dict)
    predictions: dict = field(default_factory=dict)
    min_snr_db: float = 80.0
    kernel_predictions: dict = field(default_factory=dict)

    @property
    def spec(self) -> Target:
        """The registered target (templates, variants, host runner, manifest formats)."""
        return get_target(self.target)

    @property
    def variants(self) -> list:
        """The planned variants of the target, in its order."""
        return [v for key, v in self.spec.variants.items() if key in self.predictions]

    def design(self, key: str):
        """The design of variant ``key`` ('q15' or 'float')."""
        return self.designs[self.spec.variants[key].plan_field]

    @property
    def fixed(self) -> FixedDesign | None:
        return self.designs.get("fixed")

    @property
    def floating(self) -> FloatDesign | None:
        return self.designs.get("floating")

    @property
    def cmsis(self) -> CmsisTables | None:
        return self.designs.get("cmsis")

    @property
    def provenance(self) -> dict:
        ident = self.model.identification or {}
        return {"path": self.model.path, "file": self.model_file, "hash": model_hash(self.model),
                "gamma": ident.get("gamma"), "order": self.model.order}


def plan_firmware(model: Model, *, variant: str = "both", fs: float | None = None, target: str = "generic",
                  min_snr: float = 80.0, allow_unstable: bool = False, order: int | None = None,
                  scaling: str = "linf", headroom_db: float = 6.0, quantiser: str = "efb",
                  model_file: str | None = None) -> Plan:
    """Design everything for ``generate_firmware``; raises a CodegenError subclass on refusal."""
    spec = get_target(target)
    selected = spec.selected(variant)
    if quantiser not in QUANTISERS:
        raise CodegenError(f"quantiser must be one of {', '.join(QUANTISERS)}; found {quantiser!r}")
    realisation = realise(model, fs=fs, order=order, allow_unstable=allow_unstable)
    cascade = design_cascade(realisation, scaling=spec.scaling or scaling, headroom_db=headroom_db)
    inputs = DesignInputs(cascade=cascade, realisation=realisation, polynomial=model.input_nonlinearity,
                          quantiser=quantiser, min_snr=float(min_snr))
    designs, predictions, kernel_predictions = {}, {}, {}
    # Integer variants first: where two variants share a plan field (cmsis), the one that chose a kernel wins.
    for chosen in sorted(selected, key=lambda v: not v.exact):
        designed = chosen.design(inputs)
        designs.setdefault(chosen.plan_field, designed.design)
        predictions[chosen.key] = designed.prediction
        kernel_predictions.update(designed.kernel_predictions)
    predictions = {key: predictions[key] for key in spec.variants if key in predictions}
    for key, prediction in predictions.items():
        if prediction.snr_db < min_snr:
            raise PrecisionError(refusal_reason(f"{key} variant", prediction, min_snr))
    return Plan(model=model, model_file=model_file, realisation=realisation, cascade=cascade, target=target,
                designs=designs, predictions=predictions, min_snr_db=float(min_snr),
                kernel_predictions=kernel_predictions)
