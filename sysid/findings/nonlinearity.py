"""Static input nonlinearity (Hammerstein): residual correlated with u^2 and u^3 (effects.md).

With the model's linear part L (delay and LTI core), the sweep residual e is
regressed on L(u), L(u^2 - mean), L(u^3) (``sysid.estimation.input_polynomial``): a polynomial
v = a1 u + a2 u^2 + a3 u^3 in front of L predicts e = L(v) - L(u), fitted in the validation band.
The finding is significant when the harmonic columns explain enough of the residual, far beyond chance.
For u = A sin, a2 u^2 gives a second harmonic a2 A/2 and a3 u^3 a third a3 A^2/4
relative to the fundamental; the levels are stated for A the session's largest input
amplitude (noise recording and sweeps), as ``simulate --effect input-nonlinearity`` gives them.

The same regression runs on the noise recording, whose Gaussian excitation makes it a test of the
nonlinearity alone: every linear misfit of the model, time-varying or not, is a linear functional of u and so
uncorrelated with the higher Hermite components of a Gaussian u (u^2 - sigma^2, u^3 - 3 sigma^2 u: Bussgang's
theorem, the Wiener-Hermite expansion; Schetzen, The Volterra and Wiener Theories of Nonlinear Systems, ch. 10),
which the harmonic columns carry beyond the linear one. It finds a nonlinearity the noise recording drives and
the sweeps hardly do (the seed's FB path: the noise recording peaks 13 dB above the sweeps, a cubic at H3
-22 dB there is -51 dB on the sweeps, and the linear part the identification fitted through it at 4 states for 7
leaves the sweeps a misfit the harmonic columns explain 3 % of; on the noise recording 28 %).

On exponential sweeps the harmonics are also measured directly (Farina's separation,
``sysid.estimation.input_nonlinearity.sweep_harmonics``) and set beside the model's own at the sweeps'
amplitude: ``measured_h2_db``/``measured_h3_db`` and ``model_h2_db``/``model_h3_db`` in the params, the
levels against the sweep's frequency in the evidence (the diagnosis figure draws them). A harmonic
the model lacks that stands well above the output noise in its window (``FARINA_SNR``) makes the
finding significant by itself: a linear part far from the truth (a strong saturation hides modes from
the identification) leaves the regression too little to explain, the separated harmonic stays.
The other way round, a harmonic the regression claims that the separated responses would show above
their noise but do not (``refuted_by_sweeps``) is no nonlinearity: a linear misfit on a clean session
can follow the harmonic columns, the sweeps' separation cannot invent harmonics.
"""

from __future__ import annotations

import numpy as np

from ..estimation.input_nonlinearity import harmonic_levels, sweep_harmonics
from ..estimation.input_polynomial import input_polynomial
from . import DiagnosisContext, finding, noise_prediction, uses
from .dynamics import has_series_factor, with_series_factor

__all__ = ["nonlinearity_finding", "refuted_by_sweeps"]

# The harmonic columns must explain this fraction of the residual energy left by the
# linear column, and be far beyond chance (N times the relative gain, ~chi^2 with 2 dof).
EXPLAINED = 0.10
CHI2 = 100.0
PLAUSIBLE_DB = -10.0
# Or, on exponential sweeps, a harmonic's separated response (Farina) this many times the output noise's
# power in its window (the sweeps' difference; clean random helmets read 0.9-1.2, a tanh at H3 -15 dB 2.4e5)
# and MISSED_DB above the model's own level: a harmonic the model lacks, seen even where a grossly wrong
# linear part leaves the residual regression too little to explain (random helmet 5 fb, tanh H3 -15 dB:
# identified at 4 states for 16, 1205x the floor, the harmonic columns explain 4 %).
FARINA_SNR = 4.0
MISSED_DB = 6.0


def _levels(a2: float, a3: float, amplitude: float) -> tuple[float, float]:
    """The second and third harmonics (re the fundamental, linear) of v = u + a2 u^2 + a3 u^3 at a sine of
    ``amplitude``: a2 A / 2 and a3 A^2 / 4."""
    return abs(a2) * amplitude / 2, abs(a3) * amplitude**2 / 4


def _plausible(a2: float, a3: float, amplitude: float) -> bool:
    """Whether both harmonics of u + a2 u^2 + a3 u^3 at a sine of ``amplitude`` lie below ``PLAUSIBLE_DB``."""
    return max(_levels(a2, a3, amplitude)) < 10 ** (PLAUSIBLE_DB / 20)


def refuted_by_sweeps(a2: float, a3: float, measured) -> bool:
    """Whether Farina's separation on the sweeps refutes the regression's polynomial a2 u^2 + a3 u^3: every
    harmonic it claims at the sweeps' amplitude A (H2 = |a2| A / 2, H3 = |a3| A^2 / 4, dB re the fundamental) that
    would stand ``FARINA_SNR`` above the output noise in its window is measured ``MISSED_DB`` or more below the
    claim, and at least one would. A static nonlinearity puts its harmonics on a sine of any frequency, so a
    claim the separated responses do not show is the regression fitting something else (a linear misfit:
    random helmet 535 FB, delay read 2 samples long, 82x the floor, H3 claimed -29.7 dB, -64.9 measured at
    the noise)."""
    if measured.snr is None:
        return False
    claims = dict(zip((2, 3), _levels(a2, a3, measured.amplitude)))
    seen = []
    for k, claim in claims.items():
        claim_db = 20 * np.log10(max(claim, 1e-12))
        noise_db = measured.levels_db[k] - 10 * np.log10(max(measured.snr[k], 1e-300))
        if claim_db >= noise_db + 10 * np.log10(FARINA_SNR):
            seen.append(measured.levels_db[k] <= claim_db - MISSED_DB)
    return bool(seen) and all(seen)


@uses("noise-prediction")
def nonlinearity_finding(ctx: DiagnosisContext) -> dict:
    # What a significant series factor leaves: the factor applies to every column.
    factor = (lambda column: with_series_factor(ctx, column)) if has_series_factor(ctx) else None
    fit = input_polynomial(ctx.model, ctx.sweeps, ctx.comparison.per_sweep, factor)
    explained, chi2, a2, a3 = fit.explained, fit.chi2, fit.a2, fit.a3
    # The harmonic levels are stated at the session's largest input (as ``simulate`` states them): the
    # noise recording's peaks, a few standard deviations of its excitation, lie above the sweeps'
    # amplitude (random helmets: 1.6-5.4 dB, so H2 read 1.6-5.4 dB and H3 twice that too low).
    amplitude = float(max(np.max(np.abs(r.u)) for r in (ctx.noise, *ctx.sweeps)))
    h2, h3 = (20 * np.log10(max(level, 1e-12)) for level in _levels(a2, a3, amplitude))
    # Harmonics above -10 dB are no loudspeaker or amplifier nonlinearity but a sign that the
    # residual is something else that u^3 happens to correlate with (input noise, drift). Judged at
    # the sweeps' amplitude, where the regression is fitted: the cubic read at the noise recording's
    # peaks says nothing of a saturation (the seed's FB path, tanh H3 -20 dB at its sweeps' 0.008 FS,
    # noise peaks at 0.066 FS: +5.8 dB, and a clear nonlinearity went unnamed).
    swept = float(max(np.max(np.abs(r.u)) for r in ctx.sweeps))
    plausible = _plausible(a2, a3, swept)
    significant = explained >= EXPLAINED and chi2 >= CHI2 and plausible
    score = min(explained / EXPLAINED, chi2 / CHI2)
    # The noise recording's regression, its levels judged at that recording's peak, where it was fitted.
    clipped = ctx.finding("clipping")
    clipped = clipped is not None and clipped["significant"]
    prediction = noise_prediction(ctx)
    noise_fit = input_polynomial(ctx.model, [ctx.noise], [{"linear": prediction, "residual": ctx.noise.y - prediction}],
                                 factor)
    noise_plausible = _plausible(noise_fit.a2, noise_fit.a3, float(np.max(np.abs(ctx.noise.u))))
    noise_score = min(noise_fit.explained / EXPLAINED, noise_fit.chi2 / CHI2)
    # A clipped ear channel is a nonlinearity after the path, which the columns would take for one before it.
    noise_significant = not clipped and noise_plausible and noise_score >= 1.0
    if noise_significant and noise_score > score:
        score = noise_score
    explanation = (f"the residual follows u^2 and u^3 through the path: second harmonic {h2:.1f} dB and third "
                   f"{h3:.1f} dB at the session's largest input {amplitude:.3g} FS (headphone Bl(x)/Kms(x) or amplifier); "
                   f"they explain {100 * explained:.0f} % of the remaining error")
    params = {"a2": a2, "a3": a3, "h2_db": h2, "h3_db": h3, "amplitude_fs": amplitude}
    evidence = {"explained_fraction": explained, "chi2": chi2, "noise_explained_fraction": noise_fit.explained,
                "noise_chi2": noise_fit.chi2}
    explanation += f"; on the noise recording {100 * noise_fit.explained:.0f} %"
    measured = sweep_harmonics(ctx.sweeps)
    if measured is not None:
        model = harmonic_levels(ctx.model.static_input_nonlinearity, measured.amplitude)
        # A clipped ear channel has harmonics of its own (the clipper's, after the path): they name clipping.
        if measured.snr is not None and not clipped:
            missed = [measured.snr[k] / FARINA_SNR for k in (2, 3)
                      if measured.levels_db[k] >= model[k] + MISSED_DB and measured.levels_db[k] < PLAUSIBLE_DB]
            # Each route's claim against the separated harmonics; a refuted route names nothing.
            refuted = refuted_by_sweeps(a2, a3, measured)
            noise_refuted = refuted_by_sweeps(noise_fit.a2, noise_fit.a3, measured)
            significant = significant and not refuted
            noise_significant = noise_significant and not noise_refuted
            if (refuted and explained >= EXPLAINED) or (noise_refuted and noise_score >= 1.0):
                explanation += ("; but the sweeps' separated harmonics (Farina) lie more than "
                                f"{MISSED_DB:g} dB below what the regression claims where they would stand out of the "
                                "noise: the residual is a linear misfit the harmonic columns happen to follow")
            if missed and max(missed) >= 1.0:
                significant, score = True, max(score, 1.0 + float(np.log10(max(missed))))
            evidence.update(harmonic_snr={str(k): float(v) for k, v in measured.snr.items()},
                            refuted_by_sweeps=bool(refuted), noise_refuted_by_sweeps=bool(noise_refuted))
        params.update(sweep_amplitude_fs=float(measured.amplitude), measured_h2_db=float(measured.levels_db[2]),
                      measured_h3_db=float(measured.levels_db[3]), model_h2_db=float(model[2]), model_h3_db=float(model[3]))
        evidence.update(harmonic_frequencies_hz=measured.frequencies_hz.tolist(),
                        measured_h2_curve_db=measured.curves_db[2].tolist(), measured_h3_curve_db=measured.curves_db[3].tolist())
        explanation += (f"; on the sweeps (amplitude {measured.amplitude:.3g} FS) H2 {measured.levels_db[2]:.1f} dB and "
                        f"H3 {measured.levels_db[3]:.1f} dB measured, the model's {model[2]:.1f} and {model[3]:.1f} dB")
    significant = significant or noise_significant
    return finding("input-nonlinearity", significant, score, params, explanation,
                   "refine --add input-nonlinearity:7", evidence)
