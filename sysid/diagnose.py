"""Diagnose what a model misses: ranked findings, each naming a physical effect (design.md).

``diagnose(model, noise, sweeps)`` compares the model with the sweeps
(``sysid.compare``) and runs one detector per effect (``sysid.findings``):

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

Findings are sorted significant first, then by score; on data with no missing
effect nothing is significant. A delay and a series factor can both explain a
phase lag; only the one that explains the sweeps better stays significant.
"""

from __future__ import annotations

import time


from .compare import compare
from .corrections import corrected
from .errors import IdentificationError
from .findings import DiagnosisContext
from .findings.data_quality import clipping_finding, dc_offset_finding
from .findings.delay import delay_finding
from .findings.dynamics import dynamics_findings
from .findings.disturbance import disturbance_finding
from .findings.input_noise import input_noise_finding
from .findings.nonlinearity import nonlinearity_finding
from .findings.under_modelled import under_modelled_finding
from .findings.variation import clock_drift_finding, time_variation_finding
from .model import Model
from .recordings import Recording, check_same_rate
from .thresholds import TRANSIENT_S

__all__ = ["diagnose", "Diagnosis", "format_findings", "DETECTORS"]

# Each detector returns one finding or a list of them. The series factors come first: the delay
# settles a tie with them, and the later detectors see what a significant factor leaves;
# under-modelled is asked last, when nothing named explains the error.
DETECTORS = (dc_offset_finding, clipping_finding, dynamics_findings, delay_finding, nonlinearity_finding,
             disturbance_finding, input_noise_finding, clock_drift_finding, time_variation_finding,
             under_modelled_finding)


class Diagnosis(list):
    """The ranked findings (a list of dicts) with the comparison they were based on."""

    def __init__(self, findings, comparison, seconds: float):
        super().__init__(findings)
        self.comparison = comparison
        self.seconds = seconds

    @property
    def significant(self) -> list[dict]:
        return [f for f in self if f["significant"]]


def diagnose(model: Model, noise: Recording, sweeps: list[Recording], transient_s: float = TRANSIENT_S,
             comparison=None) -> Diagnosis:
    """Ranked findings for ``model`` on one noise recording and two repeated sweeps."""
    t0 = time.perf_counter()
    if len(sweeps) != 2:
        raise IdentificationError(f"need exactly two validation sweeps; found {len(sweeps)}")
    check_same_rate([noise, *sweeps])
    model.check_stable()
    if noise.duration <= transient_s + 0.5:
        raise IdentificationError(f"{noise.path}: shorter than the {transient_s:g} s transient plus 0.5 s")
    comparison = comparison or compare(model, sweeps)
    # The detectors see the recordings as the model does: the ear clock resampled by its clock_ratio.
    noise = corrected(noise, model.clock_ratio)
    sweeps = [corrected(s, model.clock_ratio) for s in sweeps]
    ctx = DiagnosisContext(model, noise, sweeps, comparison, transient_s)
    findings = ctx.cache["findings"] = []
    for detector in DETECTORS:
        found = detector(ctx)
        findings.extend(found if isinstance(found, list) else [found])
    # A finding that biases the others' linear reference (a long missing delay) leads; then by score.
    findings.sort(key=lambda f: (not f["significant"], not f["evidence"].get("leads", False), -f["score"]))
    return Diagnosis(findings, comparison, time.perf_counter() - t0)


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
