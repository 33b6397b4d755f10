"""Refine a model: add the structure of one physical effect and re-identify (design.md).

``refine(model, noise, sweeps, "delay:23")`` looks the effect up in the registry
(``sysid.effects``): its parameters (``refine_params``; those left at None are
estimated from the data by the effect's ``complete``, with the detectors'
estimators) and its builder (``sysid.refits``: the structure or the data
correction, then the core re-identified behind it).

Every refinement is validated with ``compare`` before and after and appended to the
model's ``history``; a refit that is unstable raises, and one that makes the
validation error worse is flagged (``step["worse"]``) and, in ``refine_auto``, rejected.
``refine_auto`` repeats diagnose -> add the top significant finding -> refit,
monotone and bounded (see its docstring); the data corrections it finds pending
are applied together, then one re-identification (``refine_corrections``).

Both hold the model to a state cap (``max_order``: what the board can afford; by default the
cap the model was identified under, ``identification["max_order"]``, if any): a step that adds
states (``states``, the order after it, or ``extra_order``) is cut to the cap, and ``refine_auto``
stops at the cap saying how far from the floor the model is and what more states would buy.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass

from . import effects as registry
from . import refits
from .core.effect_spec import EffectSpec, parse_effect
from .core.errors import HelmetAncError, IdentificationError
from .core.model import Model
from .core.thresholds import AT_FLOOR, MAX_AUTO_STEPS, RUN_TO_RUN_MIN, TRANSIENT_S, WORSE
from .diagnose import diagnose
from .findings.context import detector_context
from .findings.input_noise import bound_ratio
from .identify import IdentificationOptions
from .io.recordings import Recording
from .refits import REFIT_OPTIONS
from .refits.state_cap import at_cap, held_to_cap, more_states, state_cap, within_cap
from .validation.compare import Comparison, compare

__all__ = ["REFINE_EFFECTS", "NOT_REFINABLE", "REFIT_OPTIONS", "Refinement", "RefinementStep", "AutoRefinement",
           "refine", "refine_corrections", "refine_auto", "format_refinement", "parse_refinement", "state_cap"]


class _RegistryView(Mapping):
    """A read-only view of the registry: effect name -> ``value(effect)`` for the effects ``keep`` selects."""

    def __init__(self, keep, value):
        self._keep, self._value = keep, value

    def _selected(self) -> dict:
        return {e.name: self._value(e) for e in registry.effects() if self._keep(e)}

    def __getitem__(self, name):
        return self._selected()[name]

    def __iter__(self):
        return iter(self._selected())

    def __len__(self):
        return len(self._selected())


# Structures ``refine --add`` can add (name -> parameters; a parameter left at None is estimated
# from the data), and the effects that are no model structure, with the reason.
REFINE_EFFECTS = _RegistryView(lambda e: e.refinable, lambda e: e.refine_params)
NOT_REFINABLE = _RegistryView(lambda e: not e.refinable and bool(e.not_refinable), lambda e: e.not_refinable)


@dataclass
class RefinementStep:
    """One step of refinement as recorded in a model's ``history`` (rms values in FS).

    ``worse``: the validation rms rose by more than ``WORSE``; ``accepted``: whether
    ``refine_auto`` kept the step (None outside ``refine_auto``); ``note``: why not.
    """

    effect: str
    params: dict
    rms_before: float
    rms_after: float
    noise_floor_before: float
    noise_floor_after: float
    order_before: int
    order_after: int
    worse: bool = False
    accepted: bool | None = None
    score: float | None = None
    note: str = ""

    def to_dict(self) -> dict:
        """JSON-safe dict (the entry of a model's ``history``)."""
        data = {name: getattr(self, name) for name in self.__dataclass_fields__}
        return {k: v for k, v in data.items() if v is not None and v != ""}

    @classmethod
    def from_dict(cls, data: dict) -> "RefinementStep":
        known = {k: v for k, v in data.items() if k in cls.__dataclass_fields__}
        known.setdefault("params", {})
        for name in ("rms_before", "rms_after", "noise_floor_before", "noise_floor_after", "order_before", "order_after"):
            known.setdefault(name, float("nan"))
        return cls(**known)


@dataclass
class Refinement:
    """One refinement: the new model, its history entry, and the comparisons before and after."""

    model: Model
    step: RefinementStep
    before: Comparison
    after: Comparison


def parse_refinement(text: str) -> EffectSpec:
    """Parse ``EFFECT[:PARAMS]`` for ``refine --add``; effects that are no model structure are refused."""
    kind = str(text).partition(":")[0].strip().lower()
    if kind in NOT_REFINABLE:
        raise IdentificationError(f"--add {text!r}: {kind} is not a model structure ({NOT_REFINABLE[kind]})")
    return parse_effect(text, REFINE_EFFECTS, "--add")


def _complete(spec: EffectSpec, model, noise, sweeps, before, transient_s) -> dict:
    """Fill parameters left at None from the data (the effect's ``complete``: the detectors' estimators)."""
    params = dict(spec.params)
    effect = registry.get(spec.kind)
    if effect.complete is not None:
        params = effect.complete(params, detector_context(model, noise, sweeps, before, transient_s), before)
    missing = [name for name, value in params.items() if value is None and name != "gain_db"]
    if missing:
        raise IdentificationError(f"--add {spec.kind}: give {', '.join(missing)} (e.g. {spec.kind}:{missing[0]}=...)")
    for name in ("f0_hz", "corner_hz"):
        if name in params and params[name] >= model.fs / 2:
            raise IdentificationError(f"--add {spec.kind}: {name} must be below fs/2 = {model.fs / 2:g} Hz")
    return params


def refine(model: Model, noise: Recording, sweeps: list[Recording], effect, options: IdentificationOptions | None = None,
           transient_s: float = TRANSIENT_S, before: Comparison | None = None, max_order: int | None = None,
           progress=None) -> Refinement:
    """Add one effect's structure (``"delay:23"``, an ``EffectSpec``, ...) and re-identify, holding the model to
    the state cap (``state_cap``). ``progress(text)``, when given, is told when the refit starts (after the
    step's parameters are checked, so a refused step prints nothing else)."""
    spec = effect if isinstance(effect, EffectSpec) else parse_refinement(effect)
    if spec.kind not in REFINE_EFFECTS:
        raise IdentificationError(f"--add {spec.kind}: {NOT_REFINABLE.get(spec.kind, 'not a model structure')}")
    cap = state_cap(model, max_order)
    before = before or compare(model, sweeps)
    params = held_to_cap(spec.kind, _complete(spec, model, noise, sweeps, before, transient_s), model, cap)
    if progress is not None:
        progress(f"adding {spec.kind} and refitting")
    effect = registry.get(spec.kind)
    refined, extra = effect.build(model, noise, sweeps, params, options, transient_s)
    if cap is not None and refined.order > max(cap, model.order):
        raise IdentificationError(f"refining with {spec.kind} gave {refined.order} states, above the state cap of "
                                  f"{cap} (--max-order); the model is left unchanged")
    if max_order is not None:
        # The cap the user set is the model's from now on (``state_cap``'s default for the next refinement).
        refined.identification["max_order"] = cap
    if refined.clock_ratio != 1.0 and effect.correct is None and refined.stable:
        # The clock ratio was read against a model that lacked this structure, whose misfit (harmonics,
        # say) biased the reading: read again against the refined model, kept only if it pays.
        tuned = refits.refined_clock(refined, noise, sweeps, options, transient_s)
        if tuned.clock_ratio != refined.clock_ratio:
            refined, extra = tuned, {**extra, "clock_ratio": tuned.clock_ratio}
    return _refinement(model, refined, spec.kind, params, extra, before, sweeps)


# ``refine_corrections`` applies a time-base correction (the clock) first: the others are read on the ear
# signal it resamples.
def _correction_rank(spec: EffectSpec) -> int:
    return 0 if registry.get(spec.kind).time_base else 1


def refine_corrections(model: Model, noise: Recording, sweeps: list[Recording], specs: list[EffectSpec],
                       options: IdentificationOptions | None = None, transient_s: float = TRANSIENT_S,
                       before: Comparison | None = None) -> Refinement:
    """Apply several data corrections (effects of kind "correction": clock ratio, clipped stretches,
    output offset) and re-identify once, on data corrected for all of them (``sysid.refits.correct_data``).

    One step in the history, its ``effect`` the corrections' names joined by "+" (a time-base one first),
    its ``params`` theirs together.
    """
    before = before or compare(model, sweeps)
    specs = sorted(specs, key=_correction_rank)
    for spec in specs:
        if registry.get(spec.kind).correct is None:
            raise IdentificationError(f"--add {spec.kind}: not a data correction")
    completed = [(registry.get(s.kind).correct, _complete(s, model, noise, sweeps, before, transient_s)) for s in specs]
    refined, extra = refits.correct_data(model, noise, sweeps, completed, options, transient_s)
    params = {k: v for _, p in completed for k, v in p.items()}
    return _refinement(model, refined, "+".join(s.kind for s in specs), params, extra, before, sweeps)


def _refinement(model, refined, kind, params, extra, before, sweeps) -> Refinement:
    """The refined model validated, its step recorded in its history."""
    if not refined.stable:
        raise IdentificationError(f"refining with {kind} gave an unstable model (pole radius "
                                  f"{refined.spectral_radius:.6f}); the model is left unchanged")
    after = compare(refined, sweeps)
    if refined.delay != model.delay and kind != "delay":
        # The re-identification found latency beyond the model's delay (identify's estimate on the
        # data behind it); the step says so, since the delay line changed with the structure.
        extra = {**extra, "total_delay_samples": refined.delay}
    step = RefinementStep(kind, {**{k: list(v) if isinstance(v, tuple) else v for k, v in params.items()}, **extra},
                          before.rms, after.rms, before.noise_floor, after.noise_floor, model.order, refined.order,
                          worse=bool(after.rms > WORSE * before.rms))
    refined.history = list(model.history) + [step.to_dict()]
    refined.identification.update({"rms": after.rms, "noise_floor": after.noise_floor, "order": refined.order})
    return Refinement(refined, step, before, after)


def _auto_spec(found: dict) -> EffectSpec:
    """The step ``refine --auto`` takes for a finding: the effect's ``auto_params`` of its parameters."""
    return EffectSpec(found["effect"], registry.get(found["effect"]).auto_params(found["params"]))


def _auto_effects() -> set[str]:
    """Effects ``refine --auto`` can add: those with a structure and a rule for its parameters."""
    return {e.name for e in registry.effects() if e.refinable and e.auto_params is not None}


def _corrections() -> set[str]:
    # Data corrections go first, then the disturbance (what is not the plant): every later estimate
    # is better on corrected data. They may still lower the error at the floor: the disturbance
    # inflates the noise floor itself.
    return {e.name for e in registry.effects() if e.kind in ("correction", "disturbance")}


@dataclass
class AutoRefinement:
    """What ``refine_auto`` did: the final model, every step tried (kept or not) and why it stopped."""

    model: Model
    steps: list[RefinementStep]
    stop_reason: str
    before: Comparison
    after: Comparison


def _step_key(specs: list[EffectSpec], model: Model) -> str:
    """What makes two steps the same: effects and parameters, and the model they start from (its history)."""
    return json.dumps({"effects": [{"effect": spec.kind, "params": {k: _brief(v) for k, v in spec.params.items()}}
                                   for spec in specs], "order": model.order, "from": len(model.history)},
                      sort_keys=True)


def _passes(accept: str, before: Comparison, after: Comparison, needed: float, bound: float = 1.0) -> bool:
    """Whether a step lowered the error by an effect's rule (``Effect.accept``); ``needed``: the run-to-run
    noise of the validation rms (FS); ``bound``: the validation rms over the floor that no model gets
    below (the input channel's noise through the refined model, ``sysid.findings.input_noise.bound_ratio``)."""
    if accept == "full-band":
        # An offset lives at DC, outside the validation band: it must lower the full-band rms
        # and leave the in-band rms within its run-to-run noise.
        return after.rms_full < (1.0 - RUN_TO_RUN_MIN) * before.rms_full and after.rms <= before.rms + needed
    if accept == "not-worse":
        # The errors-in-variables estimator removes a bias of the response that the validation
        # rms cannot show (the sweeps' own input noise passes through the path): H1, biased low by
        # 1 / (1 + S_nn/S_uu), is the least-squares predictor from the noisy input, so an unbiased
        # response predicts a little worse (rms^2 floor^2 + |G|^2 P_n against floor^2 + |H1|^2 ... ).
        # Kept unless worse than both the model before and the bound the input noise sets on it.
        return after.rms <= max(before.rms, bound * after.noise_floor) + needed
    return after.rms < before.rms - needed


def _allowed(effect: str, rejected: dict[str, int], retried: set[str], accepted: int) -> bool:
    """May ``effect`` be tried? A rejected effect stays rejected, except once: when a step accepted
    after its rejection changed the model (e.g. a delay added after a nonlinearity was judged
    against a linear part that lacked it), the effect is tried one more time."""
    return effect not in rejected or (rejected[effect] < accepted and effect not in retried)


def refine_auto(model: Model, noise: Recording, sweeps: list[Recording], options: IdentificationOptions | None = None,
                max_steps: int = MAX_AUTO_STEPS, transient_s: float = TRANSIENT_S, progress=None,
                max_order: int | None = None) -> AutoRefinement:
    """Diagnose -> add the top significant structure or correction -> refit, monotone and bounded.

    A step is kept only if it lowers the validation rms by more than the run-to-run
    noise of that figure (``Comparison.run_to_run``, from the two sweeps; at least
    ``RUN_TO_RUN_MIN`` of it). An effect whose step is not kept (or fails) stays
    rejected (tried at most once more after a later accepted step changed the model), no
    step (effect and parameters from the same model) is tried twice, and there are at most
    ``max_steps`` steps. The data corrections pending at a step (clock ratio, clipped
    stretches, output offset: effects with a ``correct``) are applied together before one
    re-identification (``refine_corrections``), one step naming each; kept when it passes
    the rule of any of them, and tried one at a time if not. ``stop_reason`` says why it stopped: "at the floor",
    "nothing left that lowers the error", "effects that cannot be modelled: ...", "at the state cap ..." (what
    more states would buy). ``progress(text)``, when given, is told what each step does as it starts ("step 2:
    adding delay"). The state cap: ``max_order``, or the model's own (``state_cap``); a step that adds states is
    cut to it.
    """
    say = progress or (lambda text: None)
    cap = state_cap(model, max_order)
    start = current = compare(model, sweeps)
    steps: list[RefinementStep] = []
    rejected: dict[str, int] = {}  # effect -> accepted steps before it was rejected
    retried: set[str] = set()
    tried: set[str] = set()
    stop_reason = f"step limit ({max_steps} steps)"
    diagnosis = None  # of the current model: a rejected step leaves the model, so its diagnosis, as it was
    while len(steps) < max_steps:
        if diagnosis is None:
            say(f"step {len(steps) + 1}: diagnose ({current.ratio:.2f}x the noise floor)")
            diagnosis = diagnose(model, noise, sweeps, transient_s, comparison=current)
        found = bounding_findings(diagnosis)
        bound, bounding = _error_bound(found)
        # At the floor, or at the bound an effect sets that no model gets below (the input noise).
        at_floor = current.ratio <= AT_FLOOR * bound
        auto_effects, corrections = _auto_effects(), _corrections()
        bounds = {f.effect for f in found}
        unmodellable = bounding + [f["effect"] for f in diagnosis.significant
                                   if f["effect"] not in auto_effects and f["effect"] not in bounds]
        accepted = sum(1 for step in steps if step.accepted)
        candidates = [f for f in diagnosis.significant
                      if f["effect"] in auto_effects and _allowed(f["effect"], rejected, retried, accepted)]
        # The estimator choice is made once; the data keep showing input noise afterwards.
        if any(step.get("effect") == "input-noise" for step in model.history):
            candidates = [f for f in candidates if f["effect"] != "input-noise"]
        if at_floor:
            # At the floor in band; only a data correction (an offset at DC) can still lower the error,
            # or, at a bound, the estimator that removes the bias the bound's noise puts in the response.
            candidates = [f for f in candidates if f["effect"] in corrections or f["effect"] in bounds]
            if not candidates:
                where = ("at the floor" if current.ratio <= AT_FLOOR
                         else f"at the bound that {' and '.join(sorted(bounds))} sets")
                stop_reason = where + (f"; effects that cannot be modelled: {', '.join(unmodellable)}"
                                       if unmodellable else "")
                break
        candidates.sort(key=lambda f: f["effect"] not in corrections)
        specs, capped = within_cap([(f, _auto_spec(f)) for f in candidates], model, cap)
        specs = [(f, spec) for f, spec in specs if _step_key([spec], model) not in tried]
        if not specs and not at_floor:
            # Everything named was tried and the error is still above the floor: more states are what is left
            # to try, each kept only if it pays: the long estimate's, where the tail's ladder reaches the floor
            # (too few states beyond what the model holds to call the tail dense, but the data's own), then one
            # more mode (diagnose's under-modelled without the named findings).
            for fallback in more_states(diagnosis, model):
                if not _allowed(fallback["effect"], rejected, retried, accepted):
                    continue
                more, held = within_cap([(fallback, _auto_spec(fallback))], model, cap)
                capped = capped or held
                specs = [(f, spec) for f, spec in more if _step_key([spec], model) not in tried]
                if specs:
                    break
        if not specs:
            stop_reason = (at_cap(cap, model, current, diagnosis) if capped else
                           "effects that cannot be modelled: " + ", ".join(unmodellable) if unmodellable
                           else "nothing left that lowers the error")
            break
        # Every pending data correction (clock ratio, clipped stretches, offset) in one step before one
        # re-identification: each alone would re-identify on data that still hold the others. Once that
        # combination was tried (and not kept), they are tried one at a time.
        data = [(f, spec) for f, spec in specs if registry.get(spec.kind).correct is not None]
        choice = data if len(data) >= 2 and _step_key([s for _, s in data], model) not in tried else specs[:1]
        chosen = [spec for _, spec in choice]
        score = max(f["score"] for f, _ in choice)
        combined = len(chosen) > 1
        tried.add(_step_key(chosen, model))
        if not combined and chosen[0].kind in rejected:
            retried.add(chosen[0].kind)
        needed = max(current.run_to_run, RUN_TO_RUN_MIN * current.rms)
        say(f"step {len(steps) + 1}: adding {' + '.join(s.kind for s in chosen)} and refitting")
        try:
            result = (refine_corrections(model, noise, sweeps, chosen, options, transient_s, current) if combined
                      else refine(model, noise, sweeps, chosen[0], options, transient_s, current, max_order=cap))
        except HelmetAncError as exc:
            # An unstable or failed refit is reported as a rejected step, never returned.
            params = {k: v for s in chosen for k, v in s.params.items()}
            steps.append(RefinementStep("+".join(s.kind for s in chosen), params, current.rms, current.rms,
                                        current.noise_floor, current.noise_floor, model.order, model.order,
                                        accepted=False, score=score, note=str(exc)))
            if not combined:
                rejected[chosen[0].kind] = accepted
            continue
        step = result.step
        step.score = score
        # A combined correction is kept when it passes the rule of any correction it applies.
        after_bound = max([1.0] + [bound_ratio(result.model, sweeps, result.after.noise_floor)
                                    for s in chosen if s.kind == "input-noise"])
        step.accepted = any(_passes(registry.get(s.kind).accept, current, result.after, needed, after_bound)
                            for s in chosen)
        if not step.accepted:
            step.note = (f"lowered the rms by {current.rms - result.after.rms:.2e} FS, not more than the run-to-run "
                         f"noise {needed:.2e} FS" if result.after.rms < current.rms else
                         "validation error unchanged" if result.after.rms == current.rms else "validation error rose")
            if not combined:
                rejected[chosen[0].kind] = accepted
        steps.append(step)
        if step.accepted:
            model = result.model
            model.history[-1] = step.to_dict()
            current = result.after
            diagnosis = None
    else:
        if current.ratio <= AT_FLOOR:
            stop_reason = "at the floor"
    return AutoRefinement(model, steps, stop_reason, start, current)


def bounding_findings(diagnosis) -> list:
    """The significant findings that bound the validation error from below (``evidence["bounds_the_error"]``,
    their ``params["bound_ratio"]`` the rms over the floor no model gets below: the input channel's noise)."""
    return [f for f in diagnosis.significant if f.evidence.get("bounds_the_error")]


def _error_bound(found: list) -> tuple[float, list[str]]:
    """(the largest bound over the floor among ``found``, the ``bounding_findings``, 1 if none; each named
    with its bound)."""
    named = []
    for f in found:
        snr = f.params.get("input_snr_db")
        named.append(f"{f.effect} (" + (f"input SNR {snr:.1f} dB: " if snr is not None else "")
                     + f"its noise through the path bounds the validation error at {f.params['bound_ratio']:.2f}x "
                     f"the noise floor)")
    return max([1.0] + [f.params["bound_ratio"] for f in found]), named


def format_refinement(steps, stop_reason: str | None = None) -> str:
    """One line per step: effect, parameters, rms before -> after, in multiples of the noise floor.

    ``steps`` are ``RefinementStep`` records or their dicts (a model's ``history``).
    """
    steps = [s if isinstance(s, RefinementStep) else RefinementStep.from_dict(s) for s in steps]
    lines = [] if steps else ["no refinement step"]
    for k, step in enumerate(steps, start=1):
        params = ", ".join(f"{name} {_brief(value)}" for name, value in step.params.items())
        if step.accepted is False:
            verdict = f"  (rejected: {step.note or 'validation error rose'})"
        elif step.worse and step.accepted is None:
            verdict = "  (WARNING: validation error rose)"
        else:
            verdict = ""
        lines.append(f"{k}. + {step.effect} ({params}): rms {step.rms_before:.3e} -> {step.rms_after:.3e} FS "
                     f"({step.rms_before / step.noise_floor_before:.2f}x -> "
                     f"{step.rms_after / step.noise_floor_after:.2f}x noise floor), "
                     f"order {step.order_before} -> {step.order_after}{verdict}")
    if stop_reason:
        lines.append(f"stopped: {stop_reason}")
    return "\n".join(lines)


def _brief(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)):
        return "/".join(_brief(v) for v in value[:8]) + ("/..." if len(value) > 8 else "")
    return str(value)
