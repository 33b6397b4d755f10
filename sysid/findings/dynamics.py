"""Missing series dynamics: a resonance, a high-pass or a low-pass factor (effects.md).

What a model lacks in series with it shows on the sweeps as the ratio of the
measured to the predicted ear signal. For each family of factors F_theta of
``sysid.core.structures`` the parameters are fitted to the sweeps' DFT bins inside the
validation band,

    min_theta  sum_sweeps (2 / L) sum_k |Y_k - F_theta(f_k) P_k|^2,

where P_k is the model's prediction (its input polynomial, delay and core) and Y_k
the measured ear signal without the model's disturbance lines. With F = 1 this is
``compare``'s rms (Parseval), so the fitted cost is the validation rms the model
would have with the factor in series. The search scores a coarse grid of starting
points, then runs a bounded quasi-Newton search (L-BFGS-B) from the best one, on
the bins compressed to 1 Hz cells (``sysid.validation.CompressedValidation``).
Families:

- ``resonance``: the peaking biquad (f0, Q, gain in dB) - a mode the model lacks;
- ``highpass``: first or second order, corner in Hz - a microphone or codec DC filter;
- ``lowpass``: first or second order Butterworth - an anti-alias or reconstruction filter.

Nothing is fitted when the model is within ``EXCESS`` of the noise floor. A
family is the finding when it lowers the rms by ``GAIN``, removes at least
``SHARE`` of the error power above the noise floor, and its fit is not held at a
bound of its parameters. Among families within ``SIMPLER`` of each other the one with fewer
parameters wins (a peaking factor with a low f0 imitates a high-pass shelf). The
other families are reported, not significant. ``arbitrate`` (called by the delay
detector, which runs next) settles a tie with a delay: both are series factors, and
the one that explains the sweeps better is kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.signal

from ..core import structures
from ..core.thresholds import EXCESS, EXPLAINS_GAIN, HIGHPASS_RANGE, LOWPASS_RANGE, SKIP_S, VALIDATION_BAND
from ..core.thresholds import FACTOR_EDGE as EDGE
from ..core.thresholds import FACTOR_SHARE as SHARE
from ..core.thresholds import FACTOR_SIMPLER as SIMPLER
from ..core.thresholds import RESONANCE_F0_RANGE as F0_RANGE
from ..core.thresholds import RESONANCE_GAIN_RANGE_DB as GAIN_RANGE_DB
from ..core.thresholds import RESONANCE_MIN_GAIN_DB as MIN_GAIN_DB
from ..core.thresholds import RESONANCE_Q_RANGE as Q_RANGE
from ..validation.sweeps import CompressedValidation, SweepSpectrum, rms_from_responses
from . import DiagnosisContext, finding, provider, uses

__all__ = ["dynamics_findings", "arbitrate", "with_series_factor", "factor_residual", "within_resonance", "SweepBins",
           "sweep_bins", "FactorFit", "fit_factor", "FAMILIES", "series_factor_finding", "has_series_factor"]

GAIN = EXPLAINS_GAIN
FAMILIES = ("resonance", "highpass", "lowpass")
# The fits run on the sweeps compressed to cells this wide (``sysid.validation.CompressedValidation``);
# the chosen factor's rms is then evaluated exactly.
CELL_HZ = 1.0
RESONANCE_SEARCHES = 3


@dataclass
class SweepBins:
    """The sweeps as (prediction, measurement) spectra: ``U`` of each ``SweepSpectrum`` is the model's prediction."""

    spectra: list[SweepSpectrum]
    compressed: CompressedValidation
    fs: float

    def rms(self, response=None) -> float:
        """Exact validation rms with a factor in series; ``response(frequencies)`` gives its response."""
        factors = [1.0 if response is None else response(s.frequencies) for s in self.spectra]
        return rms_from_responses(self.spectra, factors)


def sweep_bins(ctx: DiagnosisContext, band=VALIDATION_BAND) -> SweepBins:
    """The comparison's sweeps as DFT bins (after the first ``SKIP_S``) in ``band`` (Hz); in the
    validation band, the shared value ``sweep-bins`` (computed once per context)."""
    return ctx.value("sweep-bins") if tuple(band) == tuple(VALIDATION_BAND) else _sweep_bins(ctx, band)


@provider("sweep-bins")
def _sweep_bins(ctx: DiagnosisContext, band=VALIDATION_BAND) -> SweepBins:
    first = int(round(SKIP_S * ctx.fs))
    spectra = []
    for entry, sweep in zip(ctx.comparison.per_sweep, ctx.sweeps):
        linear = entry["linear"]
        # ``predicted`` holds the model's disturbance lines too; they belong to the measurement side.
        measured = sweep.y - (entry["predicted"] - linear)
        p, y = linear[first:], measured[first:]
        f = np.fft.rfftfreq(p.size, 1 / ctx.fs)
        inside = (f >= band[0]) & (f <= band[1])
        spectra.append(SweepSpectrum(f[inside], np.fft.rfft(p)[inside], np.fft.rfft(y)[inside], p.size, ctx.fs))
    return SweepBins(spectra, CompressedValidation(spectra, CELL_HZ), ctx.fs)


def factor_response(family: str, params: dict, frequencies, fs: float) -> np.ndarray:
    """Response at frequencies (Hz) of a factor given by its finding's parameters."""
    return structures.factor_response(*structures.factor_coefficients(family, params, fs), frequencies, fs)


@dataclass
class FactorFit:
    family: str
    params: dict
    rms: float
    parameter_count: int
    interior: bool


def _fit(bins: SweepBins, family: str, starts: list[dict], searches: int = 1) -> FactorFit:
    """Best fit of one family: quasi-Newton searches from the ``searches`` best of the starting points."""
    top = min(bins.spectra[0].frequencies.max(), 0.95 * bins.fs / 2)
    cells = bins.compressed.frequencies
    if family == "resonance":
        bounds = [(np.log(F0_RANGE[0]), np.log(F0_RANGE[1] * top)), tuple(np.log(Q_RANGE)), GAIN_RANGE_DB]

        def unpack(x):
            return {"f0_hz": float(np.exp(x[0])), "q": float(np.exp(x[1])), "gain_db": float(x[2])}

        def pack(p):
            return [np.log(p["f0_hz"]), np.log(p["q"]), p["gain_db"]]
    else:
        limits = HIGHPASS_RANGE if family == "highpass" else LOWPASS_RANGE
        bounds = [(np.log(limits[0]), np.log(min(limits[1], 0.95 * bins.fs / 2)))]
        order = starts[0]["order"]

        def unpack(x):
            return {"corner_hz": float(np.exp(x[0])), "order": order}

        def pack(p):
            return [np.log(p["corner_hz"])]

    def interior(x):
        # A fit held at a bound is not described by the family (a shelf is no resonance).
        return all(lo + EDGE < v < hi - EDGE for v, (lo, hi) in zip(x, bounds[:2]))

    # z^-1 at the cell edges once: each evaluation is then a ratio of two short polynomials.
    z1 = np.exp(-2j * np.pi * cells / bins.fs)

    def on_cells(x):
        b, a = structures.factor_coefficients(family, unpack(x), bins.fs)
        return np.polyval(np.asarray(b)[::-1], z1) / np.polyval(np.asarray(a)[::-1], z1)

    def cost(x):
        return float(bins.compressed.rms(on_cells(x))[0])

    # The starting points are scored together; the bounded quasi-Newton searches run from the best.
    x0s = [[min(max(v, lo), hi) for v, (lo, hi) in zip(pack(start), bounds)] for start in starts]
    scores = bins.compressed.rms(np.array([on_cells(x) for x in x0s]))
    best = None
    for k in np.argsort(scores)[:searches]:
        result = scipy.optimize.minimize(cost, x0s[k], method="L-BFGS-B", bounds=bounds, options={"maxiter": 60})
        if best is None or result.fun < best[0]:
            best = (result.fun, unpack(result.x), interior(result.x))
    params = best[1]
    rms = bins.rms(lambda f: factor_response(family, params, f, bins.fs))
    return FactorFit(family, params, rms, len(bounds), best[2])


def _resonance_starts(ctx: DiagnosisContext) -> list[dict]:
    """A grid over the band (f0 11 % apart, a few Q, a peak and a dip) and the worst bands' centres."""
    top = F0_RANGE[1] * VALIDATION_BAND[1]
    f0 = list(np.geomspace(F0_RANGE[0], top, 48))
    rows = [r for r in ctx.comparison.bands if F0_RANGE[0] <= r["center_hz"] <= top and np.isfinite(r["ratio"])]
    f0 += [r["center_hz"] for r in sorted(rows, key=lambda r: -r["ratio"])[:2]]
    return [{"f0_hz": f, "q": q, "gain_db": g} for f in f0 for q in (2.0, 6.0, 18.0) for g in (-6.0, 6.0)]


def fit_factor(ctx: DiagnosisContext, family: str) -> FactorFit:
    """The best series factor of one family for the model on the context's sweeps."""
    bins = sweep_bins(ctx)
    if family == "resonance":
        # A narrow mode makes the cost a sharp valley in f0: several searches, from distinct starts.
        return _fit(bins, family, _resonance_starts(ctx), searches=RESONANCE_SEARCHES)
    corners = np.geomspace(*(HIGHPASS_RANGE if family == "highpass" else LOWPASS_RANGE), 12)
    fits = [_fit(bins, family, [{"corner_hz": c, "order": order} for c in corners]) for order in (1, 2)]
    # The second order must pay for itself.
    return fits[1] if fits[1].rms * SIMPLER < fits[0].rms else fits[0]


def _phase_and_gain(family, params, frequency, fs):
    h = factor_response(family, params, [frequency], fs)[0]
    return float(np.degrees(np.angle(h))), float(20 * np.log10(abs(h)))


def _explain(fit: FactorFit, gain: float, fs: float) -> tuple[str, str]:
    p = fit.params
    if fit.family == "resonance":
        kind = "peak" if p["gain_db"] >= 0 else "dip"
        explanation = (f"the sweep error has a narrow {kind} at {p['f0_hz']:.0f} Hz that follows the input: a mode "
                       f"the model lacks (Q {p['q']:.1f}, {p['gain_db']:+.1f} dB; the ear canal's quarter-wave "
                       f"resonance lies near 3.4 kHz, helmet cavity modes at 16-315 Hz); a peaking factor there "
                       f"lowers the sweep error {gain:.2f}x")
        remedy = f"refine --add resonance:f0_hz={p['f0_hz']:.4g},q={p['q']:.3g},gain_db={p['gain_db']:.3g}"
    else:
        # (where the filter shows, how its phase reads there, its physical origin)
        edge, sign, wording, origin = {
            "highpass": (VALIDATION_BAND[0], 1, "magnitude error and phase lead in the lowest octaves",
                         "a MEMS microphone's roll-off (28-75 Hz) or a codec's DC-removal filter"),
            "lowpass": (VALIDATION_BAND[1], -1, "error rising towards the top of the band with phase lag",
                        "an anti-alias or reconstruction filter or a microphone's roll-off")}[fit.family]
        phase, level = _phase_and_gain(fit.family, p, edge, fs)
        explanation = (f"{wording}: a {fit.family.replace('pass', '-pass')} of order {p['order']} at "
                       f"{p['corner_hz']:.1f} Hz ({sign * phase:.0f} deg {'lead' if sign > 0 else 'lag'} and "
                       f"{level:.1f} dB at {edge:g} Hz), as from {origin}; it lowers the sweep error {gain:.2f}x")
        remedy = f"refine --add {fit.family}:corner_hz={p['corner_hz']:.4g},order={p['order']}"
    return explanation, remedy


@uses("sweep-bins")
def dynamics_findings(ctx: DiagnosisContext) -> list[dict]:
    """One finding per family of series factors; at most one of them significant."""
    if ctx.excess < EXCESS:
        return [finding(family, False, 0.0, {}, "not tested: the model is at the noise floor", "none")
                for family in FAMILIES]
    before = sweep_bins(ctx).rms()
    floor = ctx.comparison.noise_floor
    fits = {family: fit_factor(ctx, family) for family in FAMILIES}
    # Fewer parameters win among near-equals: sort by rms, then let a simpler family within SIMPLER take the lead.
    ranked = sorted(fits.values(), key=lambda f: f.rms)
    leader = ranked[0]
    for other in ranked[1:]:
        if other.parameter_count < leader.parameter_count and other.rms <= SIMPLER * leader.rms:
            leader = other
    findings = []
    for family in FAMILIES:
        fit = fits[family]
        gain = before / fit.rms if fit.rms > 0 else 0.0
        excess_power = max(before**2 - floor**2, 1e-300)
        share = (before**2 - fit.rms**2) / excess_power
        significant = (fit is leader and gain >= GAIN and share >= SHARE and fit.interior
                       and (family != "resonance" or abs(fit.params["gain_db"]) >= MIN_GAIN_DB))
        explanation, remedy = _explain(fit, gain, ctx.fs)
        if not significant:
            reason = (f"{leader.family} explains the sweeps better" if fit is not leader else
                      "the best fit lies at the edge of the family's range" if not fit.interior else
                      f"a {fit.params['gain_db']:+.1f} dB peak is no resonance" if gain >= GAIN and share >= SHARE else
                      f"it removes only {100 * max(share, 0):.0f} % of the error above the noise floor")
            explanation = f"not significant ({reason}); best {family} factor: " + explanation
            remedy = "none"
        params = dict(fit.params)
        findings.append(finding(family, significant, gain / GAIN, params, explanation, remedy,
                                {"rms_over_floor": ctx.excess, "rms_gain": gain, "explained_share": share,
                                 "rms_with_factor": fit.rms}))
    # Later detectors (which declare they need these effects) judge what a significant factor
    # leaves (a big linear misfit correlates with u^3 too): ``series_factor_finding``.
    return findings


def series_factor_finding(ctx: DiagnosisContext):
    """The significant series-factor finding among the context's findings so far, or None (read by the
    detectors that declare they need the series factors)."""
    return next((f for f in ctx.findings_of(*FAMILIES) if f["significant"]), None)


def has_series_factor(ctx: DiagnosisContext) -> bool:
    return series_factor_finding(ctx) is not None


def factor_residual(ctx: DiagnosisContext, residual: np.ndarray, prediction: np.ndarray) -> np.ndarray:
    """The residual with the significant series factor applied to the model's prediction."""
    return residual + prediction - with_series_factor(ctx, prediction) if has_series_factor(ctx) else residual


def within_resonance(ctx: DiagnosisContext, frequency: float) -> bool:
    """Is frequency (Hz) inside the -3 dB band f0 +- f0/Q of a significant resonance?

    What is left of a lightly damped mode after its fitted factor still rings there,
    and looks like a line against a flat input spectrum.
    """
    found = series_factor_finding(ctx)
    if found is None or found["effect"] != "resonance":
        return False
    return abs(frequency - found["params"]["f0_hz"]) <= found["params"]["f0_hz"] / found["params"]["q"]


def with_series_factor(ctx: DiagnosisContext, x: np.ndarray) -> np.ndarray:
    """x through the significant series factor found by ``dynamics_findings`` (x itself when none)."""
    found = series_factor_finding(ctx)
    if found is None:
        return x
    return scipy.signal.lfilter(*structures.factor_coefficients(found["effect"], found["params"], ctx.fs), x)


def arbitrate(delay: dict, ctx: DiagnosisContext) -> None:
    """When the delay finding and a series factor (``dynamics_findings``, run before) are both
    significant, keep the one that explains the sweeps better.

    Both are factors in series with the model: z^-d against the fitted family on the
    same sweep bins. The loser is marked not significant, with the reason; a factor
    that loses no longer shapes what later detectors see.
    """
    factor = series_factor_finding(ctx)
    if factor is None or not delay["significant"]:
        return
    bins = sweep_bins(ctx)
    delay_rms = bins.rms(lambda f: np.exp(-2j * np.pi * f * delay["params"]["samples"] / bins.fs))
    if delay["evidence"].get("refit_gain"):
        # Found by refits (the model's poles were bent to mimic it): judged by what the refit reaches.
        delay_rms = min(delay_rms, ctx.comparison.rms / delay["evidence"]["refit_gain"])
    factor_rms = factor["evidence"]["rms_with_factor"]
    loser, winner = (factor, delay) if delay_rms <= factor_rms else (delay, factor)
    loser["significant"] = False
    loser["explanation"] = f"not significant ({winner['effect']} explains the sweeps better); " + loser["explanation"]
    loser["remedy"] = "none"
