"""Compare a model with the measured sweeps: fit, error against the noise floor, residual tests.

The model is simulated on each measured sweep input (from rest); the residual is
measured minus predicted ear signal after the first ``SKIP_S`` of each sweep.
When the model carries a disturbance model, sinusoids at its frequencies are
fitted to each recording's residual and removed, from the residual and from the
ear signals that give the noise floor (a disturbance is not coherent between
repeats, so it would otherwise count as noise).

Figures (design.md, "Compare, diagnose, refine"; full-scale units):

- ``fit_percent`` = 100 (1 - ||y - y_hat|| / ||y - mean(y)||) over both sweeps,
  the NRMSE fit of MATLAB's ``compare``;
- ``rms`` in the validation band via Parseval (``sysid.validation``), ``rms_full``
  without the band limit, ``noise_floor`` from the two repeats;
- third-octave bands 20 Hz - 5 kHz: error and noise RMS and their ratio;
- residual tests of Ljung (System Identification, 2nd ed., section 16.6) as
  MATLAB ``resid``: normalised autocorrelation r_e(k)/r_e(0), k = 0..M-1, with
  the 99 % bound 2.58/sqrt(N); residual-input cross-correlation
  r_eu(k) = (1/N) sum_t e(t) u(t-k), k = -M+1..M-1, normalised by
  sqrt(r_e(0) r_u(0)), with the bound 2.58 sqrt(P) / (sqrt(N) sqrt(r_e(0) r_u(0))),
  P = r_e(0) r_u(0) + 2 sum_{k=1}^{M-1} r_e(k) r_u(k) (effects.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.errors import IdentificationError
from ..io.corrections import corrected, excluded_mask
from ..io.lines import fit_sinusoids
from ..io.recordings import Recording, check_same_rate
from .sweeps import (SKIP_S, VALIDATION_BAND, aligned_ears, band_energy, band_rms, check_repeats, noise_floor,
                     repeat_lag, validation_start)

__all__ = ["Comparison", "compare", "format_comparison", "third_octave_bands", "worst_bands", "LAGS", "BOUND_99",
           "START_Q"]

LAGS = 25
BOUND_99 = 2.58
# Quality factor of a mode started at a worst band (``worst_bands``): the under-modelled finding's
# trial mode and the start of ``refine --add under-modelled``'s modes.
START_Q = 3.0


def third_octave_bands(low: float = 20.0, high: float = 5000.0) -> list[tuple[float, float, float]]:
    """(center, lower, upper) edges in Hz of the base-10 third-octave bands (IEC 61260) from low to high."""
    bands = []
    for k in range(-20, 12):
        center = 1000.0 * 10.0 ** (k / 10.0)
        if low / 1.05 <= center <= high * 1.05:
            bands.append((center, center * 10.0 ** (-0.05), center * 10.0 ** 0.05))
    return bands


@dataclass
class Comparison:
    """What ``compare`` measures; see the module docstring for definitions and units.

    ``per_sweep`` holds one dict per sweep: path, u, measured, linear (the model's
    prediction), predicted (linear plus the fitted disturbance lines), residual, fs.
    """

    fit_percent: float
    rms: float
    rms_full: float
    noise_floor: float
    bands: list[dict]
    lags: np.ndarray
    residual_autocorrelation: np.ndarray
    autocorrelation_bound: float
    cross_lags: np.ndarray
    residual_input_crosscorrelation: np.ndarray
    crosscorrelation_bound: np.ndarray
    per_sweep: list[dict] = field(default_factory=list)

    @property
    def run_to_run(self) -> float:
        """Run-to-run noise of ``rms`` (FS): half the difference of the two sweeps' own rms.

        Each sweep's rms is one run of the same measurement; their difference over
        sqrt(2) is the spread of one run, and ``rms`` averages two runs (a further sqrt(2)).
        """
        values = [s["rms"] for s in self.per_sweep if "rms" in s]
        return abs(values[0] - values[1]) / 2.0 if len(values) == 2 else 0.0

    @property
    def excluded_fraction(self) -> float:
        """Fraction of the sweep samples left out of validation (the model's excluded stretches)."""
        masks = [s["excluded"] for s in self.per_sweep if "excluded" in s]
        return float(np.mean(np.concatenate(masks))) if masks else 0.0

    @property
    def ratio(self) -> float:
        """Validation rms over the noise floor (1 = as good as the data allow)."""
        return self.rms / self.noise_floor if self.noise_floor > 0 else float("inf")

    def to_dict(self) -> dict:
        """JSON-safe summary: scalars, band table and correlation sequences (no signals)."""
        return {
            "fit_percent": float(self.fit_percent),
            "rms": float(self.rms),
            "rms_full": float(self.rms_full),
            "noise_floor": float(self.noise_floor),
            "bands": [{key: float(value) for key, value in band.items()} for band in self.bands],
            "lags": [int(k) for k in self.lags],
            "residual_autocorrelation": [float(v) for v in self.residual_autocorrelation],
            "autocorrelation_bound": float(self.autocorrelation_bound),
            "cross_lags": [int(k) for k in self.cross_lags],
            "residual_input_crosscorrelation": [float(v) for v in self.residual_input_crosscorrelation],
            "crosscorrelation_bound": [float(v) for v in self.crosscorrelation_bound],
            "sweeps": [{"path": s["path"], "samples": int(s["residual"].size), "fs": float(s["fs"])} for s in self.per_sweep],
        }


def _correlation(a: np.ndarray, b: np.ndarray, lags: np.ndarray) -> np.ndarray:
    """sum_t a(t) b(t - k) for each lag k (no normalisation); a few lags, so direct sums."""
    n = a.size
    return np.array([float(np.dot(a[k:], b[:n - k])) if k >= 0 else float(np.dot(a[:n + k], b[-k:])) for k in lags])


def compare(model, sweeps: list[Recording], band=VALIDATION_BAND, lags: int = LAGS) -> Comparison:
    """Compare ``model`` with the two repeated sweep recordings; see the module docstring."""
    if len(sweeps) != 2:
        raise IdentificationError(f"need exactly two validation sweeps; found {len(sweeps)}")
    fs = check_same_rate(sweeps)
    if fs != model.fs:
        raise IdentificationError(f"model sample rate {model.fs:g} Hz differs from the sweeps' {fs:g} Hz")
    model.check_stable()
    # The repeats' alignment depends on their inputs only: found once for both uses.
    lag = repeat_lag(*sweeps)
    check_repeats(*sweeps, lag=lag)
    # One rate (checked above), so one start; each sweep must reach past it.
    first = max(validation_start(sweep) for sweep in sweeps)
    per_sweep = []
    cleaned = []
    kept = []
    for sweep in sweeps:
        # The model's data corrections: the ear clock resampled, excluded (clipped) stretches left out.
        sweep = corrected(sweep, model.clock_ratio)
        mask = excluded_mask(sweep, model.excluded)
        linear = model.simulate(sweep.u)
        residual = sweep.y - linear
        # The lines are fitted where the model is judged: an excluded (clipped) stretch holds the
        # clipper's error, tens of times the line, and would pull the fit over the whole sweep.
        disturbance = fit_sinusoids(residual[first:], model.disturbance_frequencies, fs, keep=~mask[first:])
        disturbance = np.concatenate((np.zeros(first), disturbance))[: residual.size]
        predicted = linear + disturbance
        residual = np.where(mask, 0.0, residual - disturbance)
        per_sweep.append({"path": sweep.path, "u": sweep.u, "measured": sweep.y, "predicted": predicted,
                          "linear": linear, "residual": residual, "fs": fs, "excluded": mask})
        # Without the lines on both sides of an excluded stretch's edges: the prediction there holds the
        # fitted lines, whose phases differ from repeat to repeat (a hum of 1.7e-3 FS over 4 % of the
        # samples put 2.5e-4 FS into the repeats' difference, 3.6 times the floor).
        cleaned.append(Recording(sweep.u, np.where(mask, linear, sweep.y - disturbance), fs, sweep.path))
        kept.append(1.0 - float(np.mean(mask[first:])))

    tails = [s["residual"][first:] for s in per_sweep]
    measured = [c.y[first:] for c in cleaned]
    total = sum(t.size * k for t, k in zip(tails, kept))
    per_sweep_energy = [band_rms(t, fs, band) ** 2 * t.size for t in tails]
    for record, energy, tail, k in zip(per_sweep, per_sweep_energy, tails, kept):
        record["rms"] = float(np.sqrt(energy / (tail.size * k)))
    rms = float(np.sqrt(sum(per_sweep_energy) / total))
    rms_full = float(np.sqrt(sum(np.sum(t**2) for t in tails) / total))
    centred = np.concatenate(measured)
    fit_percent = float(100.0 * (1.0 - np.linalg.norm(np.concatenate(tails)) / np.linalg.norm(centred - centred.mean())))
    noise_pair, kept_both = _equal_where_excluded(cleaned, [s["excluded"] for s in per_sweep], lag, first)
    # The excluded samples hold no noise in the repeat difference: scale to the samples kept in both.
    floor = noise_floor(*noise_pair, band, lag=lag) / np.sqrt(max(kept_both, 1e-6))

    bands = _band_table(tails, noise_pair, fs, lag)
    lag_axis = np.arange(lags)
    cross_axis = np.arange(-lags + 1, lags)
    r_e = np.zeros(lags)
    r_u = np.zeros(lags)
    r_eu = np.zeros(cross_axis.size)
    for s, e in zip(per_sweep, tails):
        e = e - e.mean()
        u = s["u"][first:] - s["u"][first:].mean()
        r_e += _correlation(e, e, lag_axis)
        r_u += _correlation(u, u, lag_axis)
        r_eu += _correlation(e, u, cross_axis)
    r_e, r_u, r_eu = r_e / total, r_u / total, r_eu / total
    scale = np.sqrt(r_e[0] * r_u[0]) if r_e[0] > 0 and r_u[0] > 0 else 1.0
    autocorrelation = r_e / r_e[0] if r_e[0] > 0 else np.zeros(lags)
    p = r_e[0] * r_u[0] + 2.0 * float(np.sum(r_e[1:] * r_u[1:]))
    cross_bound = BOUND_99 * np.sqrt(max(p, 0.0)) / (np.sqrt(total) * scale)
    return Comparison(fit_percent, rms, rms_full, floor, bands, lag_axis, autocorrelation, BOUND_99 / np.sqrt(total),
                      cross_axis, r_eu / scale, np.full(cross_axis.size, cross_bound), per_sweep)


class _BandEnergy:
    """Band-limited energy sum_t x_band(t)^2 of one signal from a single FFT (Parseval)."""

    def __init__(self, x: np.ndarray, fs: float):
        self.power = np.abs(np.fft.rfft(x)) ** 2
        self.frequencies = np.fft.rfftfreq(x.size, 1 / fs)
        self.size = x.size

    def energy(self, low: float, high: float) -> float:
        inside = (self.frequencies >= low) & (self.frequencies <= high)
        return band_energy(np.sqrt(self.power[inside]), self.size)


def _equal_where_excluded(cleaned: list[Recording], masks: list[np.ndarray], lag: int,
                          first: int) -> tuple[list[Recording], float]:
    """The two cleaned repeats with the second taking the first's value (aligned by ``lag``) wherever
    either is excluded, and the fraction of the aligned samples after ``first`` kept in both.

    An excluded stretch holds the model's prediction in place of the ear signal; where only one
    repeat is excluded there, the repeat difference would hold the model's error against the other
    repeat's measurement, and the floor would follow the model (a model ringing at fs / 2 raised it
    200-fold and read 1.1x the floor at 261x). Equal values put no noise there, whatever the model.
    """
    second = cleaned[1]
    j = np.arange(second.y.size)
    i = j + lag  # the first repeat's sample aligned with the second's sample j (``repeat_lag``)
    overlap = (i >= 0) & (i < masks[0].size) & (j < masks[1].size)
    either = np.zeros(j.size, dtype=bool)
    either[overlap] = masks[1][j[overlap]] | masks[0][i[overlap]]
    y = second.y.copy()
    y[either] = cleaned[0].y[i[either]]
    validated = overlap & (np.minimum(i, j) >= first)
    kept = 1.0 - float(np.mean(either[validated])) if np.any(validated) else 1.0
    return [cleaned[0], Recording(second.u, y, second.fs, second.path)], kept


def _band_table(tails, repeats, fs, lag) -> list[dict]:
    """Error and noise RMS in each third-octave band (noise from the difference of the aligned repeats)."""
    half = aligned_ears(repeats[0], repeats[1], SKIP_S, lag)
    n = half[0].size
    difference = _BandEnergy((half[0] - half[1]) / np.sqrt(2.0), fs)
    errors = [_BandEnergy(t, fs) for t in tails]
    total = sum(t.size for t in tails)
    rows = []
    for center, low, high in third_octave_bands():
        error = float(np.sqrt(sum(e.energy(low, high) for e in errors) / total))
        noise = float(np.sqrt(difference.energy(low, high) / n))
        rows.append({"center_hz": center, "low_hz": low, "high_hz": high, "error_rms": error, "noise_rms": noise,
                     "ratio": error / noise if noise > 0 else float("inf")})
    return rows


def worst_bands(comparison: Comparison, count: int = 1) -> list[dict]:
    """The third-octave bands (rows of the comparison's table) in the validation band with the
    largest error over noise, worst first."""
    rows = [r for r in comparison.bands if np.isfinite(r["ratio"]) and r["center_hz"] <= VALIDATION_BAND[1]]
    return sorted(rows, key=lambda r: -r["ratio"])[:count]


def format_comparison(comparison: Comparison, name: str = "model") -> str:
    """A terminal table: headline figures, then per band error vs noise with a bar in dB."""
    c = comparison
    lines = [
        f"{name}: fit {c.fit_percent:.2f} %, rms {c.rms:.3e} FS in band, {c.rms_full:.3e} FS full band, "
        f"noise floor {c.noise_floor:.3e} FS ({c.ratio:.2f}x floor)",
        "  band (Hz)        error (FS)   noise (FS)   ratio   error over noise, 1 char = 2 dB",
    ]
    for band in c.bands:
        ratio = band["ratio"]
        db = 20 * np.log10(ratio) if ratio > 0 and np.isfinite(ratio) else 0.0
        bar = "#" * int(min(max(db, 0.0), 60.0) / 2)
        flag = "  <-- above the noise floor" if ratio > 2.0 else ""
        lines.append(f"  {band['center_hz']:8.0f}  {band['error_rms']:12.3e} {band['noise_rms']:12.3e} {ratio:7.2f}   {bar}{flag}")
    worst = int(np.argmax(np.abs(c.residual_input_crosscorrelation) / c.crosscorrelation_bound))
    auto_out = int(np.sum(np.abs(c.residual_autocorrelation[1:]) > c.autocorrelation_bound))
    cross_out = int(np.sum(np.abs(c.residual_input_crosscorrelation) > c.crosscorrelation_bound))
    lines.append(f"  residual whiteness: {auto_out} of {c.lags.size - 1} lags outside the 99 % bound; "
                 f"residual-input correlation: {cross_out} of {c.cross_lags.size} lags outside "
                 f"(largest at lag {int(c.cross_lags[worst])})")
    return "\n".join(lines)
