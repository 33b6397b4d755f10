"""Static input nonlinearity (Hammerstein): residual correlated with u^2 and u^3 (effects.md).

With the model's linear part L (delay and LTI core), the sweep residual e is
regressed on L(u), L(u^2 - mean), L(u^3): a polynomial v = a1 u + a2 u^2 + a3 u^3
in front of L predicts e = L(v) - L(u), fitted in the validation band. The u^2 and u^3 columns put energy at 2f
and 3f of the sweep's instantaneous frequency, where a linear misfit at f has none.
For u = A sin, a2 u^2 gives a second harmonic a2 A/2 and a3 u^3 a third a3 A^2/4
relative to the fundamental; the levels are stated for A the session's largest input
amplitude (noise recording and sweeps), as ``simulate --effect input-nonlinearity`` gives them.
"""

from __future__ import annotations

import numpy as np
import scipy.signal

from ..validation.sweeps import SKIP_S, VALIDATION_BAND
from . import DiagnosisContext, finding, linear_part, uses
from .dynamics import has_series_factor, with_series_factor

__all__ = ["nonlinearity_finding", "polynomial_columns"]

# The harmonic columns must explain this fraction of the residual energy left by the
# linear column, and be far beyond chance (N times the relative gain, ~chi^2 with 2 dof).
EXPLAINED = 0.10
CHI2 = 100.0
PLAUSIBLE_DB = -10.0


def polynomial_columns(model, u: np.ndarray, degree: int = 3, prediction: np.ndarray | None = None) -> np.ndarray:
    """Columns L(u^k) for k = 1..degree (even powers centred), L the model's linear part.

    The first column is the model's prediction, which ``prediction`` supplies when known.
    """
    linear = linear_part(model)
    base = model.apply_input_nonlinearity(u)
    columns = [] if prediction is None else [prediction]
    for k in range(len(columns) + 1, degree + 1):
        x = base**k
        if k % 2 == 0:
            x = x - x.mean()
        columns.append(linear.simulate(x))
    return np.stack(columns, axis=1)


@uses()
def nonlinearity_finding(ctx: DiagnosisContext) -> dict:
    first = int(round(SKIP_S * ctx.fs))
    rows, targets = [], []
    for sweep, record in zip(ctx.sweeps, ctx.comparison.per_sweep):
        columns = polynomial_columns(ctx.model, sweep.u, prediction=record["linear"])
        residual = record["residual"]
        if has_series_factor(ctx):
            # What a significant series factor leaves: the factor applies to every column.
            filtered = np.stack([with_series_factor(ctx, c) for c in columns.T], axis=1)
            residual = residual + columns[:, 0] - filtered[:, 0]
            columns = filtered
        rows.append(columns[first:])
        targets.append(residual[first:])
    # Both sides in the validation band (the same linear filter keeps e = X a): the model's misfit above
    # it, where the sweep hardly excites the path, correlates with the harmonic columns by chance and
    # was taken for a nonlinearity (a clean random helmet at 1.01x the floor: 38 % "explained", 0.003 %
    # in band), and a polynomial that explains it could not lower the validation error anyway.
    band = scipy.signal.butter(4, VALIDATION_BAND, "bandpass", fs=ctx.fs, output="sos")
    X = scipy.signal.sosfilt(band, np.vstack(rows), axis=0)
    e = scipy.signal.sosfilt(band, np.concatenate(targets))
    e = e - e.mean()
    coef_linear, *_ = np.linalg.lstsq(X[:, :1], e, rcond=None)
    energy_linear = float(np.sum((e - X[:, :1] @ coef_linear) ** 2))
    coef, *_ = np.linalg.lstsq(X, e, rcond=None)
    energy_full = float(np.sum((e - X @ coef) ** 2))
    explained = (energy_linear - energy_full) / energy_linear if energy_linear > 0 else 0.0
    chi2 = e.size * (energy_linear - energy_full) / energy_full if energy_full > 0 else 0.0
    a1 = 1.0 + coef[0]
    a2, a3 = coef[1] / a1, coef[2] / a1
    # The harmonic levels are stated at the session's largest input (as ``simulate`` states them): the
    # noise recording's peaks, a few standard deviations of its excitation, lie above the sweeps'
    # amplitude (random helmets: 1.6-5.4 dB, so H2 read 1.6-5.4 dB and H3 twice that too low).
    amplitude = float(max(np.max(np.abs(r.u)) for r in (ctx.noise, *ctx.sweeps)))
    h2 = 20 * np.log10(max(abs(a2) * amplitude / 2, 1e-12))
    h3 = 20 * np.log10(max(abs(a3) * amplitude**2 / 4, 1e-12))
    # Harmonics above -10 dB are no loudspeaker or amplifier nonlinearity but a sign that the
    # residual is something else that u^3 happens to correlate with (input noise, drift).
    plausible = max(h2, h3) < PLAUSIBLE_DB
    significant = explained >= EXPLAINED and chi2 >= CHI2 and plausible
    score = min(explained / EXPLAINED, chi2 / CHI2)
    explanation = (f"the residual follows u^2 and u^3 through the path: second harmonic {h2:.1f} dB and third "
                   f"{h3:.1f} dB at the session's largest input {amplitude:.3g} FS (headphone Bl(x)/Kms(x) or amplifier); "
                   f"they explain {100 * explained:.0f} % of the remaining error")
    return finding("input-nonlinearity", significant, score,
                   {"a2": a2, "a3": a3, "h2_db": h2, "h3_db": h3, "amplitude_fs": amplitude},
                   explanation, "refine --add input-nonlinearity:3",
                   {"explained_fraction": explained, "chi2": chi2})
