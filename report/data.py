"""Everything a report shows, gathered once: spectra, comparison, findings, grid.

With an ``Identification`` the report reuses its spectra, grid and seed model. With a
model and recordings only, the spectra are re-estimated (H1), and the seed's grid is
recomputed over a modest range (``MODEST_GAMMAS`` x ``MODEST_ORDERS``: the picture of
appendix C at a fraction of the cost) or skipped (``grid="skip"``) with a note that
says why. The findings' figures read the detectors' context: a ``Diagnosis``'s own (the
shared values its detectors computed), or for findings given without it one built as
``diagnose`` builds it (``sysid.findings.context.detector_context``: the recordings as
the model sees them), whose shared values are computed when a figure first reads them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from sysid.core.errors import HelmetAncError
from sysid.core.thresholds import IDENTIFICATION_BAND, MODEST_GAMMAS, MODEST_ORDERS, TRANSIENT_S, VALIDATION_BAND
from sysid.diagnose import diagnose
from sysid.estimation.grid import GridResult, grid_search
from sysid.estimation.spectra import Spectra, estimate_spectra
from sysid.findings import DiagnosisContext
from sysid.findings.context import detector_context
from sysid.io.recordings import Recording, check_noise_length, check_same_rate
from sysid.validation.compare import Comparison, compare
from sysid.validation.sweeps import sweep_spectrum

__all__ = ["GRID_CHOICES", "MODEST_GAMMAS", "MODEST_ORDERS", "ReportData", "finding_dicts", "prepare_report_data"]

GRID_CHOICES = ("modest", "skip")


@dataclass
class ReportData:
    """Inputs of every figure and table of a report (units as in the modules they come from)."""

    model: object
    noise: Recording
    sweeps: list[Recording]
    spectra: Spectra
    comparison: Comparison
    findings: list[dict]
    context: DiagnosisContext
    grid: GridResult | None
    grid_note: str
    gamma: int | None
    seed_model: object | None
    transient_s: float = TRANSIENT_S
    notes: list[str] = field(default_factory=list)


def finding_dicts(findings) -> list[dict]:
    """Findings as plain dicts, whether given as dicts or as objects with ``to_dict()``."""
    out = []
    for f in findings or []:
        item = f.to_dict() if hasattr(f, "to_dict") else dict(f)
        item.setdefault("params", {})
        item.setdefault("evidence", {})
        out.append(item)
    return out


def prepare_report_data(model, noise: Recording, sweeps: list[Recording], identification=None, findings=None,
                        grid: str = "modest", transient_s: float = TRANSIENT_S) -> ReportData:
    """Gather a report's data; see the module docstring for what is recomputed."""
    if grid not in GRID_CHOICES:
        raise HelmetAncError(f"grid must be one of {', '.join(GRID_CHOICES)}; found {grid!r}")
    check_same_rate([noise, *sweeps])
    if noise.fs != model.fs:
        raise HelmetAncError(f"{noise.path}: sample rate {noise.fs:g} Hz differs from the model's {model.fs:g} Hz")
    check_noise_length(noise, transient_s)
    # A Diagnosis from sysid.diagnose carries the comparison it was made with.
    comparison = getattr(findings, "comparison", None) or compare(model, sweeps)
    if findings is None:
        findings = diagnose(model, noise, sweeps, transient_s=transient_s, comparison=comparison)
    context = getattr(findings, "context", None)
    if context is None:
        context = detector_context(model, noise, sweeps, comparison, transient_s)
    seed_model = None
    if identification is not None:
        spectra = identification.spectra
        grid_result = identification.grid
        gamma = grid_result.chosen.gamma
        note = "the grid of the identification run"
        if identification.seed_model is not identification.model:
            seed_model = identification.seed_model
    else:
        spectra = estimate_spectra(noise.trimmed(transient_s), "h1")
        gamma = model.identification.get("gamma")
        if grid == "modest":
            sweep_bins = [sweep_spectrum(s, VALIDATION_BAND) for s in sweeps]
            grid_result = grid_search(spectra, sweep_bins, IDENTIFICATION_BAND, MODEST_GAMMAS, MODEST_ORDERS)
            note = (f"recomputed for this report over gamma {MODEST_GAMMAS[0]}..{MODEST_GAMMAS[-1]} step "
                    f"{MODEST_GAMMAS[1] - MODEST_GAMMAS[0]} and orders {MODEST_ORDERS[0]}..{MODEST_ORDERS[-1]} "
                    "(the seed's grid is 10..1000 step 10, orders 1..20)")
            gamma = gamma if gamma is not None else grid_result.chosen.gamma
        else:
            grid_result = None
            note = ("not drawn: the report was made from a model file without its identification run, and the "
                    "grid was not recomputed (grid='skip')")
    return ReportData(model, noise, list(sweeps), spectra, comparison, finding_dicts(findings), context, grid_result,
                      note, None if gamma is None else int(gamma), seed_model, transient_s)
