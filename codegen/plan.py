"""The complete firmware design of one model: every number the generated code needs.

First step of firmware generation (plan -> context -> render -> build -> verify ->
manifest). :func:`plan_firmware` runs realisation -> sections -> the designs of the
requested variants of the target (:mod:`codegen.targets`) -> noise predictions (again with
the sections whose round-off dominates moved last, ``_quietest_order``), and
applies the refusals of the design reference: an unstable model (unless allowed) and
any variant whose predicted SNR misses the requested one. :meth:`Plan.record` is what
the manifest says of the plan. It imports the design modules and the target
descriptions, nothing of the steps after it.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from sysid.core.model import Model

from . import noise
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
# The sections moved to the end of a cascade at once, and the rounds of moving (``_quietest_order``): each round
# designs every variant again up to three times (a few seconds for a filter of 45 sections). A move is kept when
# the worst variant's round-off falls to half or less (its SNR up by 10 log10 2 dB).
_MOVED_AT_ONCE = 3
_ROUNDS = 3
_HALVED_DB = 10.0 * np.log10(2.0)
# Per plan field, the round-off each section puts at the output.
_ROUNDOFF_TERMS = {"fixed": noise.fixed_roundoff_terms, "floating": noise.float32_roundoff_terms}


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

    def record(self) -> dict:
        """What the manifest says of the plan: the target, the model, the board's rate and delay, the
        realisation, the scaled cascade, the variants' number formats and predicted figures."""
        realisation, cascade = self.realisation, self.cascade
        return {
            "target": self.target,
            "model": {**self.provenance, "fs": self.model.fs, "delay": self.model.delay,
                      "stable": self.model.stable, "spectral_radius": self.model.spectral_radius,
                      "input_nonlinearity": self.model.input_nonlinearity,
                      # A saturation form and its pre-filter are not generated: the drive passes them first.
                      **({"input_nonlinearity_form": {**self.model.input_nonlinearity_form,
                                                      "generated": "no: outside the generated linear filter"}}
                         if self.model.input_nonlinearity_form else {})},
            "board": {"fs": realisation.fs, "delay": realisation.delay, "delay_error_s": realisation.delay_error_s,
                      "resampled_from": realisation.resampled_from,
                      "delay_approximation": ("delay rounded to the nearest board sample" if realisation.resampled_from
                                              else "exact")},
            "realisation": {"form": "balanced", "hankel_singular_values": realisation.hankel_singular_values.tolist(),
                            "order": int(realisation.A.shape[0]), "truncated_from": realisation.truncated_from,
                            "truncation_error_bound": realisation.truncation_bound},
            "cascade": {"scaling": cascade.scaling, "headroom_db": cascade.headroom_db,
                        "paired_positions": list(cascade.order),
                        "realisation_error": cascade.realisation_error,
                        "margins": noise.node_margins(cascade),
                        "sections": [{"order": s.order, "b": list(s.b), "a": list(s.a), "poles": _complex_list(s.poles),
                                      "zeros": _complex_list(s.zeros)} for s in cascade.sections]},
            "formats": self.spec.formats(self),
            "predicted": {k: v.as_dict() for k, v in self.predictions.items()},
            "min_snr_db": self.min_snr_db,
        }


def _complex_list(values) -> list[list[float]]:
    return [[float(np.real(v)), float(np.imag(v))] for v in values]


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

    def designed_in(section_order, keys=None):
        """The cascade in ``section_order`` and the designs of the selected variants (those of ``keys``)."""
        cascade = design_cascade(realisation, scaling=spec.scaling or scaling, headroom_db=headroom_db,
                                 order=section_order)
        inputs = DesignInputs(cascade=cascade, realisation=realisation, polynomial=model.input_nonlinearity,
                              quantiser=quantiser, min_snr=float(min_snr))
        designs, predictions, kernel_predictions = {}, {}, {}
        # Integer variants first: where two variants share a plan field (cmsis), the one that chose a kernel wins.
        for chosen in sorted((v for v in selected if keys is None or v.key in keys), key=lambda v: not v.exact):
            designed = chosen.design(inputs)
            designs.setdefault(chosen.plan_field, designed.design)
            predictions[chosen.key] = designed.prediction
            kernel_predictions.update(designed.kernel_predictions)
        predictions = {key: predictions[key] for key in spec.variants if key in predictions}
        return cascade, designs, predictions, kernel_predictions

    cascade, designs, predictions, kernel_predictions = _quietest_order(designed_in, spec, realisation.fs)
    for key, prediction in predictions.items():
        if prediction.snr_db < min_snr:
            raise PrecisionError(refusal_reason(f"{key} variant", prediction, min_snr))
    return Plan(model=model, model_file=model_file, realisation=realisation, cascade=cascade, target=target,
                designs=designs, predictions=predictions, min_snr_db=float(min_snr),
                kernel_predictions=kernel_predictions)


def _quietest_order(designed_in, spec: Target, fs: float):
    """(cascade, designs, predictions, kernel predictions) in the paired order (``codegen.sections``: farthest
    from the unit circle first, the L-infinity scaling's order of least overflow), or with the sections whose
    round-off dominates moved to the end.

    A section's round-off passes every section after it. Where at most ``_MOVED_AT_ONCE`` sections hold more than
    half of the worst variant's round-off (``_ROUNDOFF_TERMS``; a variant without per-section terms, cmsis's,
    keeps the paired order), the loudest one, two or three are moved last together (in their order), and the
    best of those orders is kept if the worst variant's round-off at least halves (``_HALVED_DB``, the gain of
    taking the dominant terms out); then again, at most ``_ROUNDS`` times. Random helmet 7/1012's feed-forward W
    (45 sections): two pole pairs of radius 0.68-0.69 at 17-19 kHz, one with a zero at z = 1.003, second and
    third, gave 96 % of the Q15 round-off (predicted SNR 23.3 dB, float32 37.1 dB); both moved last, 53.6 and
    65.4 dB, and after the next round 56.8 and 65.4 dB. The loudest alone moved last gave 14.9 dB: the other then
    takes its scaling.
    """
    result = designed_in(None)
    order = list(range(len(result[0].sections)))
    for _ in range(_ROUNDS):
        cascade, designs, predictions, _ = result
        worst_key = min(predictions, key=lambda key: predictions[key].snr_db)
        field = spec.variants[worst_key].plan_field
        if field not in _ROUNDOFF_TERMS:
            break
        terms = np.array(_ROUNDOFF_TERMS[field](cascade, designs[field], fs))
        loudest = [int(k) for k in np.argsort(terms)[::-1][:_MOVED_AT_ONCE]]
        if np.sum(terms[loudest]) <= 0.5 * np.sum(terms):
            break
        best = predictions[worst_key].snr_db + _HALVED_DB
        chosen = None
        for count in range(1, len(loudest) + 1):
            moving = sorted(loudest[:count])
            if moving == list(range(len(order) - count, len(order))):
                continue
            moved = [k for i, k in enumerate(order) if i not in moving] + [order[i] for i in moving]
            # The worst variant first: where it does not gain, the others need not be designed.
            if designed_in(moved, {worst_key})[2][worst_key].snr_db <= best:
                continue
            candidate = designed_in(moved)
            worst = min(p.snr_db for p in candidate[2].values())
            if worst > best:
                best, chosen = worst, (moved, candidate)
        if chosen is None:
            break
        order, result = chosen
    return result
