"""Refine a model: add the structure of one physical effect and re-identify (design.md).

Structures (the model chain is [input polynomial] -> [z^-delay] -> (A, B, C, D)):

- ``delay``: more samples of pure delay; the LTI core is re-identified on the
  delayed input.
- ``input-nonlinearity``: a Hammerstein input polynomial v = u + a2 u^2 + ...,
  its coefficients by least squares on the noise recording through the current
  linear part, then the core re-identified on v.
- ``periodic-disturbance``: sinusoids at given frequencies, fitted per recording
  and removed from the ear signal before the fit; kept in the model's disturbance
  (not part of the plant) and removed again by ``compare``.
- ``highpass`` / ``lowpass`` / ``resonance`` with its gain: a fixed factor
  (``sysid.structures``) in series in front of the core; the core is refined by
  output error with the factor as a prefilter, and re-identified from scratch when
  that does not reach the noise floor (the better on the sweeps is kept); the product
  becomes (A, B, C, D). Parameters left out are fitted on the sweeps
  (``sysid.findings.dynamics``).
- ``resonance`` with f0 and Q but no gain: one more mode (2 states) started there,
  all poles refined by output error on the raw DFT data.
- ``under-modelled``: more order, as modes started at the bands worst against the
  noise floor and refined by output error, or as a fresh fit up to the higher order
  (the better on the sweeps is kept).
- ``input-noise``: the errors-in-variables estimator: bias-compensated least squares
  with the input noise density measured from the repeated sweeps
  (``sysid.output_error``).

Every refinement is validated with ``compare`` before and after and appended to the
model's ``history``; a refit that is unstable raises, and one that makes the
validation error worse is flagged (``step["worse"]``) and, in ``refine_auto``, rejected.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import scipy.signal

from .compare import Comparison, compare, fit_sinusoids
from .corrections import corrected, recording_key, without_excluded
from .diagnose import diagnose
from .effect_spec import EffectSpec, ParameterSpec, parse_effect
from .errors import HelmetAncError, IdentificationError
from .findings.data_quality import clipped_stretches_of, dc_offset_finding
from .findings.delay import scan_delay
from .findings.variation import clock_drift_finding
from .findings import DiagnosisContext
from .findings.dynamics import GAIN as FACTOR_GAIN, fit_factor
from .findings.input_noise import input_noise_density
from .findings.disturbance import disturbance_finding
from .findings.nonlinearity import nonlinearity_finding
from .findings.under_modelled import START_Q, worst_bands
from .identify import IdentificationOptions, identify
from .model import Model
from .output_error import block_data, refine_output_error
from .recordings import Recording
from .structures import factor_coefficients, factor_response, mode_block, series, tf_to_statespace, with_states
from .thresholds import AT_FLOOR, IDENTIFICATION_BAND, MAX_AUTO_STEPS, RUN_TO_RUN_MIN, TRANSIENT_S, WORSE

__all__ = ["REFINE_EFFECTS", "NOT_REFINABLE", "REFIT_OPTIONS", "Refinement", "RefinementStep", "AutoRefinement",
           "refine", "refine_auto", "format_refinement", "parse_refinement"]

# Structures ``refine --add`` can add; a parameter left at None is estimated from the data.
REFINE_EFFECTS = {
    # Data corrections the model carries (design.md, "The model"); estimated from the data.
    "dc-offset": (ParameterSpec("offset_fs", None, -1.0, 1.0),),
    "clock-drift": (ParameterSpec("ppm", None, -5000.0, 5000.0),),
    "clipping": (),
    "delay": (ParameterSpec("samples", None, 1, 2000, "int"),),
    "input-nonlinearity": (ParameterSpec("degree", 3, 2, 3, "int"),),
    "periodic-disturbance": (ParameterSpec("frequencies_hz", None, 1.0, 22000.0, "list"),),
    "input-noise": (ParameterSpec("input_noise_density", None, 0.0, 1.0),),
    "highpass": (ParameterSpec("corner_hz", None, 1.0, 5000.0), ParameterSpec("order", 1, 1, 2, "int")),
    "lowpass": (ParameterSpec("corner_hz", None, 50.0, 22000.0), ParameterSpec("order", 2, 1, 2, "int")),
    "resonance": (ParameterSpec("f0_hz", None, 20.0, 22000.0), ParameterSpec("q", 10.0, 0.5, 200.0),
                  ParameterSpec("gain_db", None, -30.0, 30.0)),
    "under-modelled": (ParameterSpec("extra_order", 2, 1, 8, "int"),),
}
NOT_REFINABLE = {
    "time-variation": "a path that changes while recording has no single model; identify per condition",
}
# The re-identification's grid: the seed's orders, gamma step 30 (as the test sessions use).
REFIT_OPTIONS = IdentificationOptions(gammas=tuple(range(10, 1001, 30)), refine_seconds=5.0)


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


def _shift(x: np.ndarray, d: int) -> np.ndarray:
    return np.concatenate((np.zeros(min(d, x.size)), x[: max(x.size - d, 0)])) if d else x


def _disturbance(model: Model, recording: Recording, frequencies) -> np.ndarray:
    """Sinusoids at frequencies fitted to the recording's residual under ``model``."""
    if not frequencies:
        return np.zeros_like(recording.y)
    return fit_sinusoids(recording.y - model.simulate(recording.u), frequencies, recording.fs)


def _prepared(model: Model, recording: Recording) -> Recording:
    """A recording with the model's data corrections: ear clock resampled, excluded stretches cut out."""
    return without_excluded(corrected(recording, model.clock_ratio), model.excluded)


def _transformed(model, recordings, input_map, frequencies) -> list[Recording]:
    """Recordings as the LTI core sees them: data corrections applied, mapped input, ear signal
    without the disturbance and the output offset."""
    prepared = [_prepared(model, r) for r in recordings]
    return [Recording(input_map(r.u), r.y - model.output_offset - _disturbance(model, r, frequencies), r.fs, r.path)
            for r in prepared]


def _reidentify(model, noise, sweeps, input_map, frequencies, options, transient_s, extra_order: int = 2,
                min_order: int | None = None) -> Model:
    recordings = _transformed(model, [noise, *sweeps], input_map, frequencies)
    options = options or REFIT_OPTIONS
    # Orders from the model's (an added structure does not take dynamics away: a lower order chosen
    # against a floor that an unmodelled effect inflates leaves the model short once the effect is
    # modelled) to two above it (the added structure, not more order, should explain the data).
    min_order = model.order if min_order is None else min_order
    orders = tuple(n for n in options.orders if min_order <= n <= model.order + extra_order) or (model.order,)
    # The core is fitted behind the model's own delay (input_map applies it): a latency found
    # again here would be dropped with the core, and a missing delay is the delay step's to add.
    options = IdentificationOptions(**{**options.__dict__, "transient_s": transient_s, "orders": orders,
                                       "latency": False})
    return identify(recordings[0], recordings[1:], model.path, options).model


def _with(model: Model, core, **changes) -> Model:
    """A copy of model with the core (A, B, C, D) and fields replaced."""
    A, B, C, D = core
    fields = dict(path=model.path, fs=model.fs, A=A, B=B, C=C, D=D, delay=model.delay,
                  input_nonlinearity=model.input_nonlinearity, disturbance_frequencies=model.disturbance_frequencies,
                  history=list(model.history), identification=dict(model.identification),
                  output_offset=model.output_offset, clock_ratio=model.clock_ratio, excluded=dict(model.excluded))
    fields.update(changes)
    return Model(**fields)


def _core(m: Model):
    return m.A, m.B, m.C, m.D


def _delay(model, noise, sweeps, params, options, transient_s):
    # The scan sees the onset of the response; a core without feedthrough starts one sample
    # later, so the delay one sample shorter is tried too and the better validation kept.
    best = None
    for total in sorted({model.delay + params["samples"], max(model.delay + params["samples"] - 1, model.delay)}):
        core = _reidentify(model, noise, sweeps, lambda u: _shift(model.apply_input_nonlinearity(u), total),
                           model.disturbance_frequencies, options, transient_s)
        trial = _with(model, _core(core), delay=total, identification=dict(core.identification))
        if not trial.stable:
            continue
        rms = compare(trial, sweeps).rms
        if best is None or rms < best[0]:
            best = (rms, trial, total)
    if best is None:
        raise IdentificationError(f"refining with delay {model.delay + params['samples']} gave no stable model")
    return best[1], {"total_samples": best[2]}


def _nonlinearity(model, noise, sweeps, params, options, transient_s):
    # a2, a3 from the sweep residual through the current linear part (the diagnosis's
    # estimator), relative to the model's own polynomial; then the core on v = poly(u).
    ctx = _context(model, noise, sweeps, compare(model, sweeps), transient_s)
    found = nonlinearity_finding(ctx)["params"]
    previous = model.input_nonlinearity or [1.0]
    added = [0.0, found["a2"], found["a3"] if params["degree"] >= 3 else 0.0]
    coefficients = [float(a + b) for a, b in zip(previous + [0.0] * (3 - len(previous)), added)] + previous[3:]
    trial = _with(model, _core(model), input_nonlinearity=coefficients)
    core = _reidentify(model, noise, sweeps, lambda u: _shift(trial.apply_input_nonlinearity(u), model.delay),
                       model.disturbance_frequencies, options, transient_s)
    return (_with(model, _core(core), input_nonlinearity=coefficients, identification=dict(core.identification)),
            {"coefficients": coefficients})


def _periodic(model, noise, sweeps, params, options, transient_s):
    frequencies = sorted(set((model.disturbance_frequencies or []) + list(params["frequencies_hz"])))
    core = _reidentify(model, noise, sweeps, lambda u: _shift(model.apply_input_nonlinearity(u), model.delay),
                       frequencies, options, transient_s)
    refit = _with(model, _core(core), disturbance_frequencies=frequencies, identification=dict(core.identification))
    return _better(sweeps, _with(model, _core(model), disturbance_frequencies=frequencies), refit), \
        {"frequencies_hz": frequencies}


def _better(sweeps, kept: Model, refit: Model) -> Model:
    """Of the model with the core kept as it is and the re-identified one, the stable one with the lower
    validation rms: a correction or disturbance model that keeps the core can only lower the error, so
    the step never makes the model worse than the structure alone does."""
    trials = [m for m in (kept, refit) if m.stable] or [kept]
    return min(trials, key=lambda m: compare(m, sweeps).rms)


def _order(model, noise, sweeps, params, options, transient_s):
    """More order: modes added at the worst bands and refined, or a fresh fit up to the higher order."""
    extra = params["extra_order"]
    data = _output_error_data(model, noise, transient_s, (options or REFIT_OPTIONS).refine_seconds)
    blocks = [mode_block(r["center_hz"], START_Q, model.fs) for r in worst_bands(compare(model, sweeps), extra // 2)]
    if extra % 2:
        blocks.append(np.array([[0.9]]))
    grown = _grown(model, data, blocks)
    core = _reidentify(model, noise, sweeps, lambda u: _shift(model.apply_input_nonlinearity(u), model.delay),
                       model.disturbance_frequencies, options, transient_s, extra_order=extra)
    fresh = _with(model, _core(core), identification=dict(core.identification))
    best = min([t for t in (grown, fresh) if t.stable] or [grown], key=lambda t: compare(t, sweeps).rms)
    return best, {"order": best.order}


def _grown(model, data, blocks) -> Model:
    """The model with new state blocks, all poles and zeros refined by output error on data."""
    A, B, C = with_states(model.A, model.B, model.C, *blocks)
    oe = refine_output_error(A, B, C, model.D, data, delay=model.delay, feedthrough=bool(model.D[0, 0]))
    return _with(model, (oe.A, oe.B, oe.C, oe.D))


def _output_error_data(model, noise, transient_s, seconds):
    body = _prepared(model, noise).trimmed(transient_s)
    y = body.y - model.output_offset - _disturbance(model, body, model.disturbance_frequencies)
    return block_data(Recording(model.apply_input_nonlinearity(body.u), y, body.fs, body.path), IDENTIFICATION_BAND,
                      seconds)


def _factor(kind):
    def build(model, noise, sweeps, params, options, transient_s):
        if kind == "resonance" and params["gain_db"] is None:
            return _mode(model, noise, sweeps, params, options, transient_s)
        b, a = factor_coefficients(kind, params, model.fs)
        factor = tf_to_statespace(b, a)
        data = _output_error_data(model, noise, transient_s, (options or REFIT_OPTIONS).refine_seconds)
        prefilter = factor_response(b, a, np.angle(data.z) * model.fs / (2 * np.pi), model.fs)
        oe = refine_output_error(model.A, model.B, model.C, model.D, data, delay=model.delay,
                                 feedthrough=bool(model.D[0, 0]), prefilter=prefilter)
        # The core kept as it is, and refined behind the factor; the better on the sweeps is kept.
        trials = [_with(model, series(factor, _core(model))), _with(model, series(factor, (oe.A, oe.B, oe.C, oe.D)))]
        scored = sorted((compare(t, sweeps).ratio, k) for k, t in enumerate(trials) if t.stable)
        if not scored or scored[0][0] > AT_FLOOR:
            # Not at the floor: either the core was bent to mimic the factor (a fresh core behind
            # the factor fixes that), or another effect is left, which a fresh core would partly
            # take in and so hide from the next diagnosis. Only a fresh core at the floor is kept.
            # A fresh core behind the factor may need fewer states: the old core had taken the factor in.
            core = _reidentify(model, noise, sweeps,
                               lambda u: scipy.signal.lfilter(b, a, _shift(model.apply_input_nonlinearity(u), model.delay)),
                               model.disturbance_frequencies, options, transient_s, min_order=1)
            fresh = _with(model, series(factor, _core(core)), identification=dict(core.identification))
            ratio = compare(fresh, sweeps).ratio if fresh.stable else np.inf
            if ratio <= AT_FLOOR or not scored:
                trials.append(fresh)
                scored = [(ratio, len(trials) - 1)]
        return trials[scored[0][1]], {"factor_order": len(a) - 1}
    return build


def _mode(model, noise, sweeps, params, options, transient_s):
    data = _output_error_data(model, noise, transient_s, (options or REFIT_OPTIONS).refine_seconds)
    grown = _grown(model, data, [mode_block(params["f0_hz"], params["q"], model.fs)])
    return grown, {"order": grown.order}


def _input_noise(model, noise, sweeps, params, options, transient_s):
    density = params["input_noise_density"]
    data = _output_error_data(model, noise, transient_s, (options or REFIT_OPTIONS).refine_seconds)
    # White input noise of one-sided density P has E|N_k|^2 = L P fs / 2 in an L-point DFT.
    variance = data.length * density * model.fs / 2.0
    oe = refine_output_error(model.A, model.B, model.C, model.D, data, delay=model.delay,
                             feedthrough=bool(model.D[0, 0]), input_noise_variance=variance)
    refined = _with(model, (oe.A, oe.B, oe.C, oe.D))
    refined.identification["estimator"] = "bias-compensated output error (errors in variables)"
    return refined, {"input_noise_density": density}


def _plain_input(model):
    return lambda u: _shift(model.apply_input_nonlinearity(u), model.delay)


def _dc_offset(model, noise, sweeps, params, options, transient_s):
    # The offset is no part of the dynamics: the core stays, the prediction gains a constant.
    return _with(model, _core(model), output_offset=model.output_offset + params["offset_fs"]), {}


def _clock_drift(model, noise, sweeps, params, options, transient_s):
    # The ear channel resampled by the ratio (composed with any ratio the model has), the core
    # re-identified on the corrected recordings.
    ratio = model.clock_ratio * (1.0 + params["ppm"] * 1e-6)
    trial = _with(model, _core(model), clock_ratio=ratio)
    # A data correction changes the data, not the dynamics: the refit keeps at least the model's order.
    core = _reidentify(trial, noise, sweeps, _plain_input(trial), trial.disturbance_frequencies, options, transient_s)
    refit = _with(trial, _core(core), identification=dict(core.identification))
    return _better(sweeps, trial, refit), {"clock_ratio": ratio}


def _clipping(model, noise, sweeps, params, options, transient_s):
    # Clipped stretches (either channel, any level, with margins) left out of identification and
    # validation; the core re-identified on what is left.
    excluded = dict(model.excluded)
    fractions = []
    for recording in (noise, *sweeps):
        spans, _ = clipped_stretches_of(corrected(recording, model.clock_ratio))
        if spans:
            excluded[recording_key(recording)] = spans
        fractions.append(sum(b - a for a, b in spans) / recording.duration)
    if not excluded:
        raise IdentificationError("--add clipping: no recording clips")
    trial = _with(model, _core(model), excluded=excluded)
    core = _reidentify(trial, noise, sweeps, _plain_input(trial), trial.disturbance_frequencies, options, transient_s)
    refit = _with(trial, _core(core), identification=dict(core.identification))
    return _better(sweeps, trial, refit), {"excluded_fraction": [round(f, 6) for f in fractions]}


_BUILDERS = {"dc-offset": _dc_offset, "clock-drift": _clock_drift, "clipping": _clipping,"delay": _delay, "input-nonlinearity": _nonlinearity, "periodic-disturbance": _periodic,
             "highpass": _factor("highpass"), "lowpass": _factor("lowpass"), "resonance": _factor("resonance"),
             "input-noise": _input_noise, "under-modelled": _order}


def _context(model, noise, sweeps, comparison, transient_s) -> DiagnosisContext:
    """What the detectors see: the recordings with the model's clock correction."""
    return DiagnosisContext(model, corrected(noise, model.clock_ratio), [corrected(s, model.clock_ratio) for s in sweeps],
                            comparison, transient_s)


def _complete(spec: EffectSpec, model, noise, sweeps, before, transient_s) -> dict:
    """Fill parameters left at None from the data (the same estimators as ``diagnose``)."""
    params = dict(spec.params)
    ctx = _context(model, noise, sweeps, before, transient_s)
    if spec.kind == "delay" and params["samples"] is None:
        best, _ = scan_delay(ctx)
        if best <= model.delay:
            raise IdentificationError("--add delay: the data show no delay beyond the model's; give delay:SAMPLES")
        params["samples"] = best - model.delay
    if spec.kind == "periodic-disturbance" and params["frequencies_hz"] is None:
        found = disturbance_finding(ctx)["params"]["frequencies_hz"]
        if not found:
            raise IdentificationError("--add periodic-disturbance: no line found in the residual; "
                                      "give periodic-disturbance:frequencies_hz=F1/F2")
        params["frequencies_hz"] = tuple(found)
    if spec.kind == "dc-offset" and params["offset_fs"] is None:
        params["offset_fs"] = dc_offset_finding(ctx)["params"]["ear_offset_fs"]
    if spec.kind == "clock-drift" and params["ppm"] is None:
        found = clock_drift_finding(ctx)
        if not found["significant"]:
            raise IdentificationError("--add clock-drift: the noise recording shows no clock drift; give clock-drift:PPM")
        params["ppm"] = found["params"]["ppm"]
    if spec.kind == "input-noise" and params["input_noise_density"] is None:
        params["input_noise_density"] = input_noise_density(sweeps)
    estimate = {"resonance": "f0_hz", "highpass": "corner_hz", "lowpass": "corner_hz"}.get(spec.kind)
    if estimate and params[estimate] is None:
        # Without its frequency the whole factor is the one that best explains the sweeps.
        fitted = fit_factor(ctx, spec.kind)
        if not fitted.interior or fitted.rms * FACTOR_GAIN > before.rms:
            raise IdentificationError(f"--add {spec.kind}: the sweeps show no {spec.kind} the model lacks; "
                                      f"give {spec.kind}:{estimate}=...")
        params.update(fitted.params)
    missing = [name for name, value in params.items() if value is None and name != "gain_db"]
    if missing:
        raise IdentificationError(f"--add {spec.kind}: give {', '.join(missing)} (e.g. {spec.kind}:{missing[0]}=...)")
    for name in ("f0_hz", "corner_hz"):
        if name in params and params[name] >= model.fs / 2:
            raise IdentificationError(f"--add {spec.kind}: {name} must be below fs/2 = {model.fs / 2:g} Hz")
    return params


def refine(model: Model, noise: Recording, sweeps: list[Recording], effect, options: IdentificationOptions | None = None,
           transient_s: float = TRANSIENT_S, before: Comparison | None = None) -> Refinement:
    """Add one effect's structure (``"delay:23"``, an ``EffectSpec``, ...) and re-identify."""
    spec = effect if isinstance(effect, EffectSpec) else parse_refinement(effect)
    if spec.kind not in _BUILDERS:
        raise IdentificationError(f"--add {spec.kind}: {NOT_REFINABLE.get(spec.kind, 'not a model structure')}")
    before = before or compare(model, sweeps)
    params = _complete(spec, model, noise, sweeps, before, transient_s)
    refined, extra = _BUILDERS[spec.kind](model, noise, sweeps, params, options, transient_s)
    if not refined.stable:
        raise IdentificationError(f"refining with {spec.kind} gave an unstable model (pole radius "
                                  f"{refined.spectral_radius:.6f}); the model is left unchanged")
    after = compare(refined, sweeps)
    step = RefinementStep(spec.kind, {**{k: list(v) if isinstance(v, tuple) else v for k, v in params.items()}, **extra},
                          before.rms, after.rms, before.noise_floor, after.noise_floor, model.order, refined.order,
                          worse=bool(after.rms > WORSE * before.rms))
    refined.history = list(model.history) + [step.to_dict()]
    refined.identification.update({"rms": after.rms, "noise_floor": after.noise_floor, "order": refined.order})
    return Refinement(refined, step, before, after)


def _auto_spec(found: dict) -> EffectSpec:
    p = found["params"]
    params = {"delay": lambda: {"samples": p["samples"]},
              "input-nonlinearity": lambda: {"degree": 3},
              "periodic-disturbance": lambda: {"frequencies_hz": tuple(p["frequencies_hz"])},
              "input-noise": lambda: {"input_noise_density": p["input_noise_density"]},
              "resonance": lambda: {"f0_hz": p["f0_hz"], "q": p["q"], "gain_db": p["gain_db"]},
              "highpass": lambda: {"corner_hz": p["corner_hz"], "order": p["order"]},
              "lowpass": lambda: {"corner_hz": p["corner_hz"], "order": p["order"]},
              "under-modelled": lambda: {"extra_order": 2},
              "dc-offset": lambda: {"offset_fs": p["ear_offset_fs"]},
              "clock-drift": lambda: {"ppm": p["ppm"]},
              "clipping": lambda: {}}[found["effect"]]()
    return EffectSpec(found["effect"], params)


AUTO_EFFECTS = ("clipping", "clock-drift", "dc-offset", "delay", "input-nonlinearity", "periodic-disturbance",
                "input-noise", "resonance", "highpass", "lowpass", "under-modelled")
# Data corrections go first, then the disturbance (what is not the plant): every later estimate
# is better on corrected data. They may still lower the error at the floor: the disturbance
# inflates the noise floor itself.
_CORRECTIONS = ("clipping", "clock-drift", "dc-offset", "periodic-disturbance")
# Corrections judged on the full-band rms (what they change lies outside the validation band).
_OUT_OF_BAND = ("dc-offset",)
# Structures that remove a bias the rms does not see, kept when the rms does not rise.
_BIAS_ONLY = ("input-noise",)


@dataclass
class AutoRefinement:
    """What ``refine_auto`` did: the final model, every step tried (kept or not) and why it stopped."""

    model: Model
    steps: list[RefinementStep]
    stop_reason: str
    before: Comparison
    after: Comparison


def _step_key(spec: EffectSpec, model: Model) -> str:
    """What makes two steps the same: effect and parameters, and the model they start from (its history)."""
    return json.dumps({"effect": spec.kind, "params": {k: _brief(v) for k, v in spec.params.items()},
                       "order": model.order, "from": len(model.history)}, sort_keys=True)


def _allowed(effect: str, rejected: dict[str, int], retried: set[str], accepted: int) -> bool:
    """May ``effect`` be tried? A rejected effect stays rejected, except once: when a step accepted
    after its rejection changed the model (e.g. a delay added after a nonlinearity was judged
    against a linear part that lacked it), the effect is tried one more time."""
    return effect not in rejected or (rejected[effect] < accepted and effect not in retried)


def refine_auto(model: Model, noise: Recording, sweeps: list[Recording], options: IdentificationOptions | None = None,
                max_steps: int = MAX_AUTO_STEPS, transient_s: float = TRANSIENT_S) -> AutoRefinement:
    """Diagnose -> add the top significant structure or correction -> refit, monotone and bounded.

    A step is kept only if it lowers the validation rms by more than the run-to-run
    noise of that figure (``Comparison.run_to_run``, from the two sweeps; at least
    ``RUN_TO_RUN_MIN`` of it). An effect whose step is not kept (or fails) stays
    rejected (tried at most once more after a later accepted step changed the model), no
    step (effect and parameters from the same model) is tried twice, and there are at most
    ``max_steps`` steps. ``stop_reason`` says why it stopped: "at the floor",
    "nothing left that lowers the error", "effects that cannot be modelled: ...".
    """
    start = current = compare(model, sweeps)
    steps: list[RefinementStep] = []
    rejected: dict[str, int] = {}  # effect -> accepted steps before it was rejected
    retried: set[str] = set()
    tried: set[str] = set()
    stop_reason = f"step limit ({max_steps} steps)"
    while len(steps) < max_steps:
        at_floor = current.ratio <= AT_FLOOR
        diagnosis = diagnose(model, noise, sweeps, transient_s, comparison=current)
        unmodellable = [f["effect"] for f in diagnosis.significant if f["effect"] not in AUTO_EFFECTS]
        accepted = sum(1 for step in steps if step.accepted)
        candidates = [f for f in diagnosis.significant
                      if f["effect"] in AUTO_EFFECTS and _allowed(f["effect"], rejected, retried, accepted)]
        if at_floor:
            # At the floor in band; only a data correction (an offset at DC) can still lower the error.
            candidates = [f for f in candidates if f["effect"] in _CORRECTIONS]
            if not candidates:
                stop_reason = "at the floor" + (f"; effects that cannot be modelled: {', '.join(unmodellable)}"
                                                if unmodellable else "")
                break
        # The estimator choice is made once; the data keep showing input noise afterwards.
        if any(step.get("effect") == "input-noise" for step in model.history):
            candidates = [f for f in candidates if f["effect"] != "input-noise"]
        candidates.sort(key=lambda f: f["effect"] not in _CORRECTIONS)
        specs = [(f, _auto_spec(f)) for f in candidates]
        specs = [(f, spec) for f, spec in specs if _step_key(spec, model) not in tried]
        if not specs and not at_floor and _allowed("under-modelled", rejected, retried, accepted):
            # Everything named was tried and the error is still above the floor: more order is what is
            # left to try (diagnose's under-modelled without the named findings); kept only if it pays.
            fallback = {"effect": "under-modelled", "params": {}, "score": 0.0}
            specs = [(fallback, spec) for spec in [_auto_spec(fallback)] if _step_key(spec, model) not in tried]
        if not specs:
            stop_reason = ("effects that cannot be modelled: " + ", ".join(unmodellable) if unmodellable
                           else "nothing left that lowers the error")
            break
        found, spec = specs[0]
        tried.add(_step_key(spec, model))
        if spec.kind in rejected:
            retried.add(spec.kind)
        needed = max(current.run_to_run, RUN_TO_RUN_MIN * current.rms)
        try:
            result = refine(model, noise, sweeps, spec, options, transient_s, current)
        except HelmetAncError as exc:
            # An unstable or failed refit is reported as a rejected step, never returned.
            steps.append(RefinementStep(spec.kind, dict(spec.params), current.rms, current.rms, current.noise_floor,
                                        current.noise_floor, model.order, model.order, accepted=False,
                                        score=found["score"], note=str(exc)))
            rejected[spec.kind] = accepted
            continue
        step = result.step
        step.score = found["score"]
        step.accepted = result.after.rms < current.rms - needed
        if spec.kind in _OUT_OF_BAND:
            # An offset lives at DC, outside the validation band: it must lower the full-band rms
            # and leave the in-band rms within its run-to-run noise.
            step.accepted = (result.after.rms_full < (1.0 - RUN_TO_RUN_MIN) * current.rms_full
                             and result.after.rms <= current.rms + needed)
        if spec.kind in _BIAS_ONLY:
            # The errors-in-variables estimator removes a bias of the response that the validation
            # rms cannot show (the sweeps' own input noise passes through the path); kept unless worse.
            step.accepted = result.after.rms <= current.rms + needed
        if not step.accepted:
            step.note = (f"lowered the rms by {current.rms - result.after.rms:.2e} FS, not more than the run-to-run "
                         f"noise {needed:.2e} FS" if result.after.rms < current.rms else
                         "validation error unchanged" if result.after.rms == current.rms else "validation error rose")
            rejected[spec.kind] = accepted
        steps.append(step)
        if step.accepted:
            model = result.model
            model.history[-1] = step.to_dict()
            current = result.after
    else:
        if current.ratio <= AT_FLOOR:
            stop_reason = "at the floor"
    return AutoRefinement(model, steps, stop_reason, start, current)


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
