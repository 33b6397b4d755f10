"""The registry itself: the ``Effect`` record, and registering, finding and ordering effects.

``sysid.effects`` re-exports every name here and registers the built-in effects, one
module each, on import; each of those modules imports ``Effect`` and ``register`` from
this module, which imports none of them.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable

from ..core.effect_spec import ParameterSpec
from ..core.errors import HelmetAncError
from .references import Resolved

__all__ = ["Effect", "register", "unregister", "registered", "get", "effects", "names", "detector_order",
           "findings_read_by", "FIGURES"]

# The figure kinds of the report (``report.diagnosis_figures``): delay-scan (fit cost against
# the delay), series-factor (measured/model response with the fitted factor over it), harmonics
# (error spectrogram with the sweep's harmonics), lines (residual spectrum with the lines), h1-h2,
# segments (per-segment responses and delays), levels (per-channel bars), mismatch (measured/model), tail
# (the data's and the model's impulse-response envelopes against the noise, the response's length marked).
FIGURES = ("delay-scan", "series-factor", "harmonics", "lines", "h1-h2", "segments", "levels", "mismatch", "tail")


@dataclass(frozen=True)
class Effect:
    """One physical effect: what simulates it, detects it, and models or corrects it.

    ``detect(ctx)`` returns one finding or a list (one detector may judge several
    effects, e.g. the series factors' family fit); ``needs`` names the effects
    whose findings it reads (``ctx.finding``, ``ctx.findings_of``: they run first, and
    no other finding is readable while it runs); ``needs_all``: it reads every other
    finding (under-modelled, asked last). The values the detector
    shares with others (the session's line search, the noise recording's prediction: each
    computed once per diagnosis by a named provider) it declares itself with
    ``sysid.findings.uses``; ``diagnose`` lets it read only those. ``build(model, noise,
    sweeps, params, options, transient_s) -> (model, extra params)`` adds the
    structure or correction; ``complete(params, ctx, before) -> params`` fills parameters
    ``refine --add`` left at None from the data; ``accept``: how ``refine --auto`` judges
    the step - "in-band" (the validation rms falls by more than its run-to-run noise),
    "full-band" (an offset at DC: the full-band rms falls, the in-band rms does not rise),
    "not-worse" (removes a bias the rms cannot show); ``not_refinable`` says why there is
    no structure. ``correct(model, noise, sweeps, params) -> (model, extra params)``: a data
    correction alone, the core kept (no re-identification); ``refine --auto`` applies every
    pending correction this way before one re-identification (``sysid.refits.correct_data``);
    ``time_base``: the correction resamples the recordings (a clock), so it is applied before
    the other corrections, which are read on the signal it produces.
    ``factor(params, fs) -> (b, a)``: the effect is a linear factor in series with
    the plant (how ``simulate`` adds it; the other built-in effects act on the
    recordings and are simulated by ``sysid.simulate`` itself). ``random(rng) ->
    (spec, estimated parameter or None, its true value or None)`` draws the effect at
    random parameters in effects.md's ranges (the tests' and benchmarks' sessions). ``kind``: "structure" (a part of the
    plant's model), "correction" (of the data: applied first by ``refine --auto``),
    "disturbance" (explains part of the output, not the plant) or "report" (named only).

    Each of the functions (``detect``, ``build``, ``complete``, ``correct``, ``auto_params``,
    ``factor``, ``random``) may be given as a reference ``"package.module:attribute"`` instead
    (``sysid.effects.references``): it is imported when the field is first read, and reads
    as the function from then on.
    """

    name: str
    summary: str
    simulate_params: tuple[ParameterSpec, ...] | None = None
    refine_params: tuple[ParameterSpec, ...] | None = None
    detect: Callable | str | None = Resolved()
    needs: tuple[str, ...] = ()
    needs_all: bool = False
    build: Callable | str | None = Resolved()
    complete: Callable | str | None = Resolved()
    correct: Callable | str | None = Resolved()
    time_base: bool = False
    accept: str = "in-band"
    not_refinable: str = ""
    auto_params: Callable[[dict], dict] | str | None = Resolved()
    kind: str = "structure"
    factor: Callable | str | None = Resolved()
    figure: str = "mismatch"
    random: Callable | str | None = Resolved()

    def has(self, name: str) -> bool:
        """Whether the function ``name`` (``"detect"``, ``"build"``, ...) is given, without importing
        what a reference names."""
        return self.__dict__[name] is not None

    def __post_init__(self):
        if self.figure not in FIGURES:
            raise HelmetAncError(f"effect {self.name}: figure must be one of {', '.join(FIGURES)}; found {self.figure!r}")
        if self.kind not in ("structure", "correction", "disturbance", "report"):
            raise HelmetAncError(f"effect {self.name}: kind must be structure, correction, disturbance or report")
        if self.accept not in ("in-band", "full-band", "not-worse"):
            raise HelmetAncError(f"effect {self.name}: accept must be in-band, full-band or not-worse")
        if self.has("correct") and self.kind != "correction":
            raise HelmetAncError(f"effect {self.name}: only a correction (kind 'correction') has a correct")
        if self.time_base and not self.has("correct"):
            raise HelmetAncError(f"effect {self.name}: time_base belongs to a data correction (one with a correct)")
        if self.has("build") and self.refine_params is None:
            raise HelmetAncError(f"effect {self.name}: a structure needs its refine_params (may be empty)")

    @property
    def refinable(self) -> bool:
        return self.has("build")

    @property
    def simulated(self) -> bool:
        return self.simulate_params is not None


_REGISTRY: dict[str, Effect] = {}


def register(effect: Effect, replace: bool = False) -> Effect:
    """Add ``effect`` to the registry (by name); a second effect of the same name needs ``replace``."""
    if effect.name in _REGISTRY and not replace and _REGISTRY[effect.name] is not effect:
        raise HelmetAncError(f"effect {effect.name!r} is registered already; pass replace=True to replace it")
    for need in effect.needs:
        if need not in _REGISTRY:
            raise HelmetAncError(f"effect {effect.name}: needs {need!r}, which is not registered")
    _REGISTRY[effect.name] = effect
    return effect


def unregister(name: str) -> None:
    """Remove an effect (a user effect registered for one session or test)."""
    _REGISTRY.pop(name, None)


@contextmanager
def registered(effect: Effect):
    """``with registered(MY_EFFECT): ...``: the effect is in the registry inside the block only."""
    previous = _REGISTRY.get(effect.name)
    register(effect, replace=True)
    try:
        yield effect
    finally:
        if previous is None:
            unregister(effect.name)
        else:
            _REGISTRY[effect.name] = previous


def get(name: str) -> Effect:
    try:
        return _REGISTRY[name]
    except KeyError:
        raise HelmetAncError(f"unknown effect {name!r}; expected one of {', '.join(_REGISTRY)}") from None


def effects() -> list[Effect]:
    """Every registered effect, in registration order."""
    return list(_REGISTRY.values())


def names() -> list[str]:
    return list(_REGISTRY)


def detector_order() -> list[Callable]:
    """The distinct detectors, each after the detectors of the effects it needs; those that read
    every finding (``needs_all``) last. Registration order breaks ties. The detectors given by
    reference are resolved (imported) here."""
    ordered: list[Callable] = []
    done: set[str] = set()
    pending = [e for e in _REGISTRY.values() if e.has("detect")]
    last = [e for e in pending if e.needs_all]
    pending = [e for e in pending if not e.needs_all]
    while pending:
        ready = next((e for e in pending
                      if all(n in done or not _REGISTRY[n].has("detect") for n in e.needs)), None)
        if ready is None:
            raise HelmetAncError("effects' detectors need each other in a cycle: " + ", ".join(e.name for e in pending))
        pending.remove(ready)
        # Effects that share one detector are done together.
        done.update(e.name for e in _REGISTRY.values() if e.detect is ready.detect)
        if ready.detect not in ordered:
            ordered.append(ready.detect)
    for effect in last:
        if effect.detect not in ordered:
            ordered.append(effect.detect)
    return ordered


def findings_read_by(detector: Callable) -> tuple[str, ...] | None:
    """The effects whose findings ``detector`` may read: those the effects it detects declare in
    ``needs`` (in registration order), or None (every finding) when one of them declares ``needs_all``."""
    judged = [e for e in _REGISTRY.values() if e.has("detect") and e.detect is detector]
    if any(e.needs_all for e in judged):
        return None
    return tuple(dict.fromkeys(need for e in judged for need in e.needs))
