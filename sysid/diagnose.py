"""Diagnose what a model misses: ranked findings, each naming a physical effect (design.md).

``diagnose(model, noise, sweeps)`` compares the model with the sweeps
(``sysid.validation.compare``) and runs the detector of every effect in the registry
(``sysid.effects``; the detectors live in ``sysid.findings``), each after the
detectors of the effects it declares it needs, reading only their findings
(``DiagnosisContext.finding``) and the shared values it declares it uses
(``sysid.findings.uses``: the noise recording's prediction, the session's one line
search, ...; each computed once per diagnosis by its provider).
The built-in effects:

- data quality, straight from the recordings: ``dc-offset``, ``clipping``;
- the plant: ``delay`` (fixed-pole delay scan), ``input-nonlinearity`` (residual
  against u^2, u^3 through the path), and ``resonance``, ``highpass``, ``lowpass``
  (series factors fitted to the sweeps, ``sysid.findings.dynamics``);
- the data, not the plant: ``periodic-disturbance`` (residual lines absent from the
  input), ``input-noise`` (input noise from the repeated sweeps, H1 bias),
  ``clock-drift`` and ``time-variation`` (segments of the noise recording);
- last, ``under-modelled``: error above the floor that no named effect explains but
  one more mode removes, and in any case error above twice the floor that nothing
  named explains (with the bands and the order it suggests).

Findings (``Finding`` records; ``Diagnosis.to_dicts`` gives the JSON of the
``helmet-anc/diagnosis@1`` contract) are sorted significant first, then by score;
on data with no missing effect nothing is significant. A delay and a series factor
can both explain a phase lag; only the one that explains the sweeps better stays
significant. A long missing delay (excess phase above ``LEADING_PHASE_DEG`` at the
top of the validation band) ranks ahead of the findings whose detectors need it
(the input polynomial is judged against the model's linear prediction, which the
delay's misfit spoils), so ``refine --auto`` adds it first.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from threadpoolctl import threadpool_limits

from . import effects as registry
from .core.errors import IdentificationError
from .core.model import Model
from .core.thresholds import TRANSIENT_S
from .findings import DiagnosisContext, Finding
from .findings.context import detector_context
from .io.recordings import Recording, check_noise_length, check_same_rate
from .validation.compare import compare

__all__ = ["diagnose", "Diagnosis", "Finding", "format_findings", "DETECTORS"]

class _Detectors(Sequence):
    """The registry's detectors in the order they run (``sysid.effects.detector_order``), read live."""

    def __getitem__(self, index):
        return registry.detector_order()[index]

    def __len__(self):
        return len(registry.detector_order())


# Each detector returns one finding or a list of them. The series factors come first: the delay
# settles a tie with them, and the later detectors see what a significant factor leaves;
# under-modelled is asked last, when nothing named explains the error.
DETECTORS = _Detectors()


class Diagnosis(list):
    """The ranked findings (``Finding`` records) with the comparison they were based on; ``seconds``
    the wall time of ``diagnose``, ``cpu_seconds`` the CPU time (s) of the comparison and of each
    detector by name, the shared values counted where first read; ``context`` the
    ``DiagnosisContext`` the detectors read, with the shared values computed during the diagnosis
    (``context.values``: what the report's figures draw)."""

    def __init__(self, findings, comparison, seconds: float, cpu_seconds: dict | None = None,
                 context: DiagnosisContext | None = None):
        super().__init__(findings)
        self.comparison = comparison
        self.seconds = seconds
        self.cpu_seconds = cpu_seconds or {}
        self.context = context

    @property
    def significant(self) -> list[Finding]:
        return [f for f in self if f.significant]

    def to_dicts(self) -> list[dict]:
        """The findings as the ``helmet-anc/diagnosis@1`` JSON's ``findings`` list."""
        return [f.to_dict() for f in self]


def diagnose(model: Model, noise: Recording, sweeps: list[Recording], transient_s: float = TRANSIENT_S,
             comparison=None) -> Diagnosis:
    """Ranked findings for ``model`` on one noise recording and two repeated sweeps."""
    t0 = time.perf_counter()
    if len(sweeps) != 2:
        raise IdentificationError(f"need exactly two validation sweeps; found {len(sweeps)}")
    check_same_rate([noise, *sweeps])
    model.check_stable()
    check_noise_length(noise, transient_s)
    # One BLAS thread: the products here are small or vectors (the comparison's correlations are dot
    # products over a sweep), where a second thread gains little, and on a shared machine OpenBLAS's
    # threads wait for each other: the comparison's 150 dot products took 0.5-0.8 s of CPU and more of
    # wall time at a load of 7, against 0.01 s with one thread.
    with threadpool_limits(limits=1, user_api="blas"):
        clock = time.process_time()
        comparison = comparison or compare(model, sweeps)
        cpu_seconds = {"compare": time.process_time() - clock}
        # The detectors see the recordings as the model does: the ear clock resampled by its clock_ratio.
        ctx = detector_context(model, noise, sweeps, comparison, transient_s)
        findings = ctx.findings
        for detector in registry.detector_order():
            # A detector that declares nothing (a user's effect written before ``uses``) reads freely.
            ctx.readable = getattr(detector, "uses", None)
            # The findings it reads are those of the effects it needs (all of them for ``needs_all``).
            ctx.readable_findings = registry.findings_read_by(detector)
            clock = time.process_time()
            try:
                found = detector(ctx)
            finally:
                ctx.readable = ctx.readable_findings = None
            cpu_seconds[getattr(detector, "__name__", str(detector))] = time.process_time() - clock
            findings.extend(found if isinstance(found, list) else [found])
    findings.sort(key=lambda f: (not f.significant, -f.score))
    findings[:] = _leading_first(findings)
    return Diagnosis(findings, comparison, time.perf_counter() - t0, cpu_seconds, ctx)


def _leading_first(findings: list[Finding]) -> list[Finding]:
    """A significant finding that biases the linear reference of other detectors (``evidence["leads"]``:
    a long missing delay) moves ahead of the findings of the effects that declare they need it
    (``Effect.needs``: the input polynomial judged on the model's linear prediction); the rest keep
    their rank by score."""
    ordered = list(findings)
    for lead in [f for f in findings if f.significant and f.evidence.get("leads")]:
        position = ordered.index(lead)
        biased = [k for k, f in enumerate(ordered[:position])
                  if f.effect in registry.names() and lead.effect in registry.get(f.effect).needs]
        if biased:
            ordered.insert(biased[0], ordered.pop(position))
    return ordered


def format_findings(findings, limit: int | None = None) -> str:
    """Terminal listing: significant findings with explanation and remedy, then the rest in one line."""
    significant = [f for f in findings if f["significant"]]
    lines = []
    if not significant:
        lines.append("no significant finding: nothing the data show is missing from the model")
    for rank, f in enumerate(significant[:limit], start=1):
        params = ", ".join(f"{k} {_short(v)}" for k, v in f["params"].items())
        lines.append(f"{rank}. {f['effect']} (score {f['score']:.1f}): {params}")
        lines.append(f"   {f['explanation']}")
        lines.append(f"   remedy: {f['remedy']}")
    rest = [f"{f['effect']} {f['score']:.2f}" for f in findings if not f["significant"]]
    if rest:
        lines.append("not significant (score): " + ", ".join(rest))
    return "\n".join(lines)


def _short(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list):
        return "[" + ", ".join(_short(v) for v in value[:6]) + (", ...]" if len(value) > 6 else "]")
    return str(value)
