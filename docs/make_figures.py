"""Make the README's figures from simulated sessions of the seed's feed-forward plant.

    python docs/make_figures.py [OUTDIR]      (default: docs/figures)

Writes, deterministically (fixed seeds, and PNG files without the matplotlib version in
their metadata, so the same numbers give the same bytes; tests/test_make_figures.py):

- ``ff-model-bode.png``: the identified FF model over the noisy and smoothed
  frequency-response estimates (the seed's figure 4.4, on a clean session);
- ``ff-error-bands.png``: on a session with a hidden 23-sample delay (chin-to-ear
  sound path plus converter latency), the error of the plant model that lacks the
  delay, per third-octave band against the noise floor: where the model fails;
- ``ff-delay-evidence.png``: the diagnosis of that model: the fit cost against the
  total delay and the phase the model misses, with the delay line.

Short sessions (8 s of noise, 2 s sweeps) and the seed's gamma grid at step 30 keep
the run to about half a minute.
"""

from __future__ import annotations

import sys
from pathlib import Path

from report.figures import error_bands_figure, finding_figure, model_bode_figure
from sysid.core.plants import appendix_a_model
from sysid.diagnose import diagnose
from sysid.estimation.spectra import estimate_spectra
from sysid.identify import IdentificationOptions, identify
from sysid.simulate import SessionSpec, simulate_session
from sysid.validation.compare import compare

__all__ = ["make_figures"]

SESSION = {"path": "ff", "noise_duration": 8.0, "sweep_duration": 2.0, "sweep_silence": 0.2}
OPTIONS = IdentificationOptions(gammas=tuple(range(10, 1001, 30)))
DPI = 110
# No "Software: Matplotlib version ..." entry: the bytes depend on the figures only.
PNG_METADATA = {"Software": None}


def make_figures(outdir: Path) -> list[Path]:
    """Write the README figures into outdir and return their paths."""
    outdir.mkdir(parents=True, exist_ok=True)
    written = []

    clean = simulate_session(SessionSpec(seed=1, **SESSION))
    result = identify(clean.noise, clean.sweeps, "ff", OPTIONS)
    figure = model_bode_figure(result.model, result.spectra, result.grid.chosen.gamma, seed_model=result.seed_model)
    written.append(outdir / "ff-model-bode.png")
    figure.savefig(written[-1], dpi=DPI, metadata=PNG_METADATA)

    delayed = simulate_session(SessionSpec(seed=2, **SESSION), effects=["delay:23"])
    lacking = appendix_a_model("ff")
    comparison = compare(lacking, delayed.sweeps)
    written.append(outdir / "ff-error-bands.png")
    error_bands_figure(comparison).savefig(written[-1], dpi=DPI, metadata=PNG_METADATA)

    findings = diagnose(lacking, delayed.noise, delayed.sweeps, comparison=comparison)
    delay = next(f for f in findings if f["effect"] == "delay")
    spectra = estimate_spectra(delayed.noise.trimmed(3.0))
    written.append(outdir / "ff-delay-evidence.png")
    # Drawn from the diagnosis's own context: the delay scan its finding was decided on.
    finding_figure(delay, findings.context, spectra).savefig(written[-1], dpi=DPI, metadata=PNG_METADATA)
    return written


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent / "figures"
    for path in make_figures(target):
        print(f"wrote {path}")
