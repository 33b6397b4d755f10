"""The limits the paths allow, per third-octave band, and what sets each one.

For the drive path S (the FB model or the true path), the chin-to-ear response H (the FF
model P, or the disturbance's own coherent response), the noise (an ``anc.disturbance.Disturbance``:
the user's recording with ANC off, or the default spectrum) and the latency L, ``feedforward_limits``
gives per band of ``anc.prediction``:

* the causal Wiener feed-forward bound: the attenuation of the best causal filter of any
  length (design.md "Control"; ``anc.wiener.causal_wiener``), computed on a dense FFT grid
  (``FeedforwardProblem``), for the ear power weighted so that every third-octave band counts
  alike (weight V = 1 / f inside 20 Hz-2 kHz, ``band_measure``; each band's attenuation is then
  its power over linear frequency, as ``anc.prediction`` integrates it). Outside the bands V is
  ``OUTSIDE_WEIGHT`` times its value at the top band edge: the bound is the best in-band result
  that does not buy it with noise outside.
  With V = 1 (the ear power on a linear grid, pink noise's low bands) the seed pair's mean
  50 Hz-1 kHz is 1.6 dB; with the band measure 11.6 dB (the reference value 11.2 dB); it depends
  on the outside weight (1e-8: 16.2 dB, 1e-10: 19.0 dB on the seed, within 1.5 dB on random pairs
  3, 5 and 12), the price of the zero of S at z = 1.0089 taken below 20 Hz or inside the bands. With G = z^-L S = G_ap G_mp and |M|^2 = Phi_xx it is
  W = -[G_ap^* H M]_+ / (G_mp M): S's delay, its relative degree and its zeros outside the unit
  circle sit in G_ap and cap it. Two regularisations keep the factors bounded, the same the
  design uses (``anc.feedforward``): the chin spectrum is floored at ``CHIN_FLOOR`` (-60 dB) of
  its peak (a microphone's self-noise; a reference with no power in a band would be perfectly
  predictable and the bound would be the non-causal one at infinite gain), and the filter's
  output is penalised by ``EFFORT_FLOOR`` (-100 dB) of the peak |G|^2 over the bands, so
  1 / G_mp stays bounded where S is tiny or has a zero on the unit circle (a coupling
  high-pass's zero at DC);
* the same bound under the design's rules (``anc.ruled_bound``): no band with noise more than the stated
  amplification limit louder, W's mean-square gain per region outside the bands at most ``MAX_GAIN_DB``; the
  Wiener bound buys attenuation with gain outside the bands wherever S or the chin path's lead keeps W from
  cancelling (random pair 1/1001: 29.2 dB mean 50 Hz-1 kHz with 103 dB of gain outside; 17.9 dB within the rules);
* the coherence bound -10 log10(1 - coh^2) (``anc.prediction.coherence_bound``);
* in words, what limits the band (``reasons``): the coherence (within ``COHERENCE_REACHED_DB``
  of it), else the larger of two counterfactual gains, each one the bound again with one cause
  removed: S's zeros outside the unit circle reflected inside (|S| kept), and then the drive
  path advanced by the k samples its excess phase lags the chin path's (k from the group delay
  of the all-pass parts, averaged over the band); a gain of ``CAUSE_DB`` or more names the cause.
  Else the band is limited by the regularisation (the drive path weak there, or the chin noise
  at its floor). Where the bound within the rules is ``CAUSE_DB`` or more below it, the reason says so and
  names the gain the bound's filter needs outside the bands.

The feedback bound is ``anc.feedback``'s; ``Limits`` has room for it (``feedback_db``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from sysid.core.errors import HelmetAncError
from sysid.core.model import Model

from .disturbance import Disturbance, vouched_response
from .prediction import BANDS, band_centres, band_grid, coherence_bound
from .ruled_bound import outside_gain_db, ruled_wiener
from .wiener import FFTGrid, allpass_split, causal_wiener, relative_floor

__all__ = ["Limits", "FeedforwardProblem", "feedforward_limits", "chin_to_ear", "regions", "region_index", "CHIN_FLOOR",
           "EFFORT_FLOOR", "OUTSIDE_WEIGHT", "COHERENCE_REACHED_DB", "CAUSE_DB", "SILENT_BAND", "MAX_AMPLIFICATION_DB",
           "MAX_GAIN_DB", "AMPLIFICATION_RANGE_DB", "RULES_CLAUSE", "RULES_PREFIX"]

CHIN_FLOOR = 1e-6
EFFORT_FLOOR = 1e-10
# The bound's weight outside 20 Hz-2 kHz relative to the band measure at the top band edge (module docstring).
OUTSIDE_WEIGHT = 1e-6
# A causal bound within this of the coherence bound is set by the coherence.
COHERENCE_REACHED_DB = 1.0
# A counterfactual that raises the bound by this much names its cause.
CAUSE_DB = 1.0
# The design's rules (``anc.design.DesignOptions``' defaults): a band may be this much louder with control (dB),
# and W's mean-square gain per region outside 20 Hz-2 kHz at most this (dB; ``anc.feedforward``).
MAX_AMPLIFICATION_DB = 6.0
MAX_GAIN_DB = 30.0
# The amplification limits a design takes (dB, open below): none, and a loop that may make a band ten times louder.
AMPLIFICATION_RANGE_DB = (0.0, 20.0)
# Appended to a band's reason where the bound within the rules is CAUSE_DB or more below the bound.
RULES_PREFIX = "; within the design's rules"
RULES_CLAUSE = (RULES_PREFIX + " {0:.1f} dB (no band more than {1:g} dB louder, W's gain outside "
                "20 Hz-2 kHz at most {2:g} dB: the bound's filter has {3:.0f} dB there, where the chin noise is at "
                "its floor)")
# A band whose ear power is below this fraction of the loudest band's has no bound worth stating.
SILENT_BAND = 1e-6
# Zeros this close to the unit circle (relative) are on it: a high-pass's zero at DC, not a non-minimum-phase zero.
_ON_CIRCLE = 1e-6
LIMITS_FORMAT = "helmet-anc/limits@1"
# Bins a region outside the bands is checked on (``FeedforwardProblem.checked``).
_CHECKED_OUTSIDE = 512


def chin_to_ear(disturbance: Disturbance, ff_model: Model | None, frequencies_hz) -> np.ndarray:
    """H at frequencies (Hz): the disturbance's coherent response (exact when it carries its FF model), else
    ``ff_model``'s (gain capped outside its band, ``anc.disturbance.vouched_response``) when given."""
    f = np.asarray(frequencies_hz, dtype=float)
    if ff_model is not None and disturbance.ff_model is None:
        return vouched_response(ff_model, f)
    return disturbance.at(f).coherent_response()


def regions(fs: float) -> list[tuple[float, float]]:
    """(lo, hi) in Hz, half open: the bands of ``anc.prediction.BANDS``, then the frequencies below the first
    and octaves above the last up to fs / 2 (where a filter must not make the ear louder either)."""
    result = [(lo, hi) for _, lo, hi in BANDS] + [(0.0, BANDS[0][1])]
    lo = BANDS[-1][2]
    while lo < fs / 2.0:
        result.append((lo, min(2.0 * lo, fs / 2.0 * (1.0 + 1e-9))))
        lo *= 2.0
    return result


def region_index(frequencies_hz: np.ndarray, fs: float) -> np.ndarray:
    """The region (``regions``) of each frequency."""
    index = np.zeros(np.shape(frequencies_hz), dtype=int)
    for number, (lo, hi) in enumerate(regions(fs)):
        index[(frequencies_hz >= lo) & (frequencies_hz < hi)] = number
    return index


class FeedforwardProblem:
    """The paths and the noise on a dense FFT grid, and the ear power per region with a filter W.

    ``G`` = z^-L S, ``H`` the chin-to-ear response, ``T`` what W cancels ((1 + G Q) H with a
    feedback loop ``loop`` = G Q, else H), ``phi`` the chin PSD floored (``CHIN_FLOOR``), ``uu``
    the incoherent ear PSD; ``effort`` the penalty R of ``anc.wiener.causal_wiener``'s floor.
    Regions (``regions``): the FFT bins inside each band of ``anc.prediction.BANDS`` (the first
    ``bands`` regions), then those outside them. ``audible``: the bands with noise (``SILENT_BAND``);
    ``ruled``: the regions the band rule holds in (the bands with noise).
    """

    def __init__(self, s_model: Model, disturbance: Disturbance, latency: int, ff_model: Model | None = None,
                 loop=None, grid: FFTGrid | None = None):
        if not disturbance.has_reference:
            raise HelmetAncError("a feed-forward limit needs the chin microphone's spectra: give a recording with "
                                 "ANC off or an FF model")
        ff_model = ff_model if ff_model is not None else disturbance.ff_model
        fs = s_model.fs
        self.fs, self.latency = fs, int(latency)
        self.grid = grid or FFTGrid.for_paths(fs, s_model.poles(), ff_model.poles() if ff_model is not None else [])
        f = self.f = self.grid.frequencies_hz
        self.G = s_model.frequency_response(f) * np.exp(-2j * np.pi * f * latency / fs)
        spectra = disturbance.at(f)
        self.H = chin_to_ear(disturbance, ff_model, f)
        # The chin path's own response for its excess phase (the vouched one is capped in gain, not in phase).
        self.chin_path = ff_model.frequency_response(f) if ff_model is not None else self.H
        self.chin = np.maximum(spectra.reference_psd, 0.0)
        self.phi = relative_floor(self.chin, CHIN_FLOOR)
        self.uu = spectra.incoherent_psd()
        self.loop = None if loop is None else loop(f)
        self.one_plus = 1.0 if self.loop is None else 1.0 + self.loop
        self.T = self.one_plus * self.H
        self.bands = len(BANDS)
        self.region = region_index(f, fs)
        inside = self.region < self.bands
        self.effort = EFFORT_FLOOR * float(np.max(np.abs(self.G[inside]) ** 2))
        # The bins a realised filter is checked on: every bin inside the bands, outside them every m-th bin
        # (at most ``_CHECKED_OUTSIDE`` a region), each standing for m bins.
        self.checked, self.check_weight = [], []
        for number in range(int(self.region.max()) + 1):
            bins = np.flatnonzero(self.region == number)
            stride = 1 if number < self.bands else max(1, bins.size // _CHECKED_OUTSIDE)
            self.checked.append(bins[::stride])
            self.check_weight.append(np.full(bins[::stride].size, bins.size / max(bins[::stride].size, 1)))
        self.checked, self.check_weight = np.concatenate(self.checked), np.concatenate(self.check_weight)
        # Ear power with the chin spectrum floored: the floor is what the rule assumes where the recording is silent.
        self.off = self.band_sum(self.uu + self.phi * np.abs(self.H) ** 2)
        self.off_with_loop = self.band_sum(np.abs(self.one_plus) ** 2 * self.uu + self.phi * np.abs(self.T) ** 2)
        self.audible = self.off[:self.bands] >= SILENT_BAND * float(np.max(self.off[:self.bands]))
        self.ruled = np.append(self.audible, np.zeros(self.off.size - self.bands, bool))
        # The band measure (module docstring): 1 / f inside the bands, OUTSIDE_WEIGHT / f_top outside.
        top = BANDS[-1][2]
        self.band_measure = np.where(inside, 1.0 / np.maximum(f, BANDS[0][1]), OUTSIDE_WEIGHT / top)

    def band_sum(self, values: np.ndarray) -> np.ndarray:
        """Sum over the bins of each region (values on every bin, or on ``checked``, weighted)."""
        values = np.real(values)
        if values.size == self.checked.size and values.size != self.f.size:
            return np.bincount(self.region[self.checked], weights=values * self.check_weight,
                               minlength=int(self.region.max()) + 1)
        return np.bincount(self.region, weights=values, minlength=int(self.region.max()) + 1)

    def outside_gain(self, W: np.ndarray) -> np.ndarray:
        """W's mean-square gain in each region outside the bands (W on every bin, or on ``checked``)."""
        return (self.band_sum(np.abs(W) ** 2) / np.maximum(self.band_sum(np.ones(W.size)), 1e-300))[self.bands:]

    def attenuation(self, W: np.ndarray, with_loop: bool = False, G: np.ndarray | None = None) -> np.ndarray:
        """Per region 10 log10(ear power without W / with W) (dB): W alone, or W with the loop against the loop
        alone; through G, or another drive path (a counterfactual's). The bands are the first ``bands``."""
        at = slice(None) if W.size == self.f.size else self.checked
        G = (self.G if G is None else G)[at]
        one_plus = self.one_plus if np.isscalar(self.one_plus) else self.one_plus[at]
        if with_loop:
            on = self.band_sum(np.abs(one_plus) ** 2 * self.uu[at] + self.phi[at] * np.abs(self.T[at] + G * W) ** 2)
            off = self.off_with_loop
        else:
            on = self.band_sum(self.uu[at] + self.phi[at] * np.abs(self.H[at] + G * W) ** 2)
            off = self.off
        return 10.0 * np.log10(np.maximum(off, 1e-300) / np.maximum(on, 1e-300))

    def wiener(self, G: np.ndarray | None = None, effort: np.ndarray | float | None = None,
               weight: np.ndarray | float | None = None) -> np.ndarray:
        """The causal Wiener filter for T on this grid (``anc.wiener.causal_wiener``), for G or another drive path,
        of least ear power in ``weight`` (None: the band measure; 1.0: the ear power on the linear grid)."""
        G = self.G if G is None else G
        effort = self.effort if effort is None else effort
        weight = self.band_measure if weight is None else weight
        return causal_wiener(G, self.T, self.phi, self.grid.points, effort, weight)


@dataclass(frozen=True)
class Limits:
    """Per band of ``bands_hz`` (dB; None where the band is silent): the causal feed-forward bound, the
    coherence bound and in words what limits it; the causal bound within the design's rules
    (``causal_ff_ruled_db``); the feedback bound when computed (``anc.feedback``)."""

    bands_hz: list[float]
    causal_ff_db: list[float | None]
    coherence_db: list[float | None]
    reasons: list[str]
    latency_samples: int
    details: dict = field(default_factory=dict)
    feedback_db: list[float | None] | None = None
    causal_ff_ruled_db: list[float | None] | None = None

    def mean(self, part: str = "causal_ff", lo_hz: float = 50.0, hi_hz: float = 1000.0) -> float:
        """Mean over the bands with centres in [lo_hz, hi_hz] of ``part`` ("causal_ff", "causal_ff_ruled",
        "coherence", "feedback")."""
        values = getattr(self, f"{part}_db")
        chosen = [v for c, v in zip(self.bands_hz, values) if lo_hz <= c <= hi_hz and v is not None]
        return float(np.mean(chosen)) if chosen else float("nan")

    def to_dict(self) -> dict:
        data = asdict(self)
        data["format"] = LIMITS_FORMAT
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "Limits":
        if not isinstance(data, dict) or data.get("format") != LIMITS_FORMAT:
            found = data.get("format") if isinstance(data, dict) else type(data).__name__
            raise HelmetAncError(f"not a limits record: format must be {LIMITS_FORMAT!r}; found {found!r}")
        try:
            limits = cls(bands_hz=[float(v) for v in data["bands_hz"]],
                         causal_ff_db=[None if v is None else float(v) for v in data["causal_ff_db"]],
                         coherence_db=[None if v is None else float(v) for v in data["coherence_db"]],
                         reasons=[str(v) for v in data["reasons"]], latency_samples=int(data["latency_samples"]),
                         details=dict(data.get("details", {})),
                         feedback_db=None if data.get("feedback_db") is None else
                         [None if v is None else float(v) for v in data["feedback_db"]],
                         causal_ff_ruled_db=None if data.get("causal_ff_ruled_db") is None else
                         [None if v is None else float(v) for v in data["causal_ff_ruled_db"]])
        except (KeyError, TypeError, ValueError) as exc:
            raise HelmetAncError(f"limits record: missing or malformed field ({exc})") from None
        for name in ("causal_ff_db", "coherence_db", "reasons", "causal_ff_ruled_db"):
            if getattr(limits, name) is not None and len(getattr(limits, name)) != len(limits.bands_hz):
                raise HelmetAncError(f"limits record: {name} has {len(getattr(limits, name))} values for "
                                     f"{len(limits.bands_hz)} bands")
        return limits


def _nonminimum_phase_zeros(s_model: Model) -> np.ndarray:
    zeros = s_model.zeros() if s_model.order else np.zeros(0, complex)
    zeros = zeros[np.isfinite(zeros)]
    return zeros[np.abs(zeros) > 1.0 + _ON_CIRCLE]


def _zero_hz(zero: complex, fs: float) -> float:
    """Where a zero acts (Hz): its angle, or for a real positive zero the corner ln|z| fs / 2 pi of its phase."""
    if abs(zero.imag) <= 1e-12 * abs(zero) and zero.real > 0.0:
        return float(np.log(abs(zero))) * fs / (2.0 * np.pi)
    return abs(float(np.angle(zero))) * fs / (2.0 * np.pi)


def _zero_words(zeros: np.ndarray, centre_hz: float, fs: float) -> str:
    """The zero of S outside the unit circle acting nearest the band (in log frequency), in words."""
    where = np.array([max(_zero_hz(z0, fs), 1e-3) for z0 in zeros])
    z0 = zeros[int(np.argmin(np.abs(np.log(where / centre_hz))))]
    if abs(z0.imag) <= 1e-12 * abs(z0):
        return f"a zero of S outside the unit circle at z = {z0.real:.4f} (its phase turns at {_zero_hz(z0, fs):.0f} Hz)"
    return f"a zero of S outside the unit circle at {_zero_hz(z0, fs):.0f} Hz (radius {abs(z0):.4f})"


def _reflected(problem: FeedforwardProblem, zeros: np.ndarray) -> np.ndarray:
    """G with each zero z0 outside the unit circle moved to 1 / conj(z0) (|G| unchanged on the circle)."""
    z = np.exp(2j * np.pi * problem.f / problem.fs)
    G = problem.G.copy()
    for z0 in zeros:
        G = G * (1.0 - np.conj(z0) * z) / (z - z0)
    return G


def _group_delay(response: np.ndarray, points: int) -> np.ndarray:
    """Group delay (samples) of the all-pass part of a response on the grid: -d(phase)/d(omega)."""
    allpass, _ = allpass_split(response, points)
    phase = np.unwrap(np.angle(allpass))
    return -np.gradient(phase, 2.0 * np.pi / points)


def _band_mean(problem: FeedforwardProblem, values: np.ndarray) -> np.ndarray:
    counts = np.maximum(problem.band_sum(np.ones(values.size)), 1.0)
    return (problem.band_sum(values) / counts)[:problem.bands]


def feedforward_limits(s_model: Model, disturbance: Disturbance, latency: int, ff_model: Model | None = None,
                       problem: FeedforwardProblem | None = None, max_amplification_db: float = MAX_AMPLIFICATION_DB,
                       max_gain_db: float = MAX_GAIN_DB) -> Limits:
    """The limits of ``s_model`` (S), the chin-to-ear response and the noise at ``latency`` samples (module docstring).

    ``ff_model``: P, when the disturbance does not carry its own (``from_recording(..., ff_model=P)``);
    without either, H is the disturbance's coherent response. ``max_amplification_db``, ``max_gain_db``: the
    design's rules the bound within the rules keeps (dB).
    """
    if not (isinstance(latency, (int, np.integer)) and latency >= 0):
        raise HelmetAncError(f"latency must be a whole number of samples >= 0; found {latency!r}")
    problem = problem or FeedforwardProblem(s_model, disturbance, latency, ff_model)
    nb = problem.bands
    wiener = problem.wiener()
    bound = problem.attenuation(wiener)[:nb]
    ruled = ruled_wiener(problem, max_amplification_db, max_gain_db)
    within_rules = problem.attenuation(ruled.W)[:nb]
    coherence = np.array(coherence_bound(disturbance.at(band_grid().reshape(-1))))
    zeros = _nonminimum_phase_zeros(s_model)
    G_reflected = _reflected(problem, zeros) if zeros.size else problem.G
    without_zeros = problem.attenuation(problem.wiener(G_reflected), G=G_reflected)[:nb] if zeros.size else bound
    lag = _band_mean(problem, _group_delay(G_reflected, problem.grid.points)
                     - _group_delay(problem.chin_path, problem.grid.points))
    lead = int(max(0, round(float(np.max(lag[problem.audible]))))) if np.any(problem.audible) else 0
    advanced = without_zeros
    if lead > 0:
        z = np.exp(2j * np.pi * problem.f / problem.fs)
        advanced = problem.attenuation(problem.wiener(G_reflected * z ** lead), G=G_reflected * z ** lead)[:nb]
    s_db = 20.0 * np.log10(np.maximum(np.sqrt(_band_mean(problem, np.abs(problem.G) ** 2)), 1e-300))
    s_db = s_db - float(np.max(s_db[problem.audible])) if np.any(problem.audible) else s_db
    outside_gain = outside_gain_db(problem, wiener)
    reasons = []
    for b in range(len(BANDS)):
        if not problem.audible[b]:
            reasons.append("no noise in this band")
            continue
        zero_gain, lag_gain = without_zeros[b] - bound[b], advanced[b] - without_zeros[b]
        if coherence[b] - bound[b] <= COHERENCE_REACHED_DB:
            reasons.append(f"coherence: the ear noise not coherent with the chin ({coherence[b]:.1f} dB bound)")
        elif zero_gain >= max(lag_gain, CAUSE_DB):
            reasons.append(_zero_words(zeros, BANDS[b][0], problem.fs) + f" (without it {without_zeros[b]:.1f} dB)")
        elif lag_gain >= CAUSE_DB:
            reasons.append(f"the chin path is faster than the drive path by {lead} samples (without that "
                           f"{advanced[b]:.1f} dB)")
        else:
            reasons.append(f"regularisation: the drive path {-s_db[b]:.0f} dB below its peak, the chin noise "
                           f"floor {10 * np.log10(CHIN_FLOOR):.0f} dB")
        if bound[b] - within_rules[b] >= CAUSE_DB:
            reasons[-1] += RULES_CLAUSE.format(within_rules[b], max_amplification_db, max_gain_db, outside_gain)
    details = {"grid_points": problem.grid.points, "chin_floor": CHIN_FLOOR, "effort_floor": EFFORT_FLOOR,
               "s_zeros_outside": [[float(z0.real), float(z0.imag)] for z0 in zeros],
               "chin_path_lead_samples": lead, "disturbance": dict(disturbance.source),
               "bound_outside_gain_db": outside_gain,
               "within_rules": {"max_amplification_db": float(max_amplification_db), "max_gain_db": float(max_gain_db),
                                "outside_gain_db": ruled.outside_gain_db, "feasible": ruled.feasible,
                                "binding": list(ruled.binding), "iterations": ruled.iterations,
                                "duality_gap_db": ruled.gap_db}}
    audible = problem.audible
    return Limits(band_centres(), [float(v) if a else None for v, a in zip(bound, audible)],
                  [float(v) if a else None for v, a in zip(coherence, audible)], reasons, int(latency), details,
                  causal_ff_ruled_db=[float(v) if a else None for v, a in zip(within_rules, audible)])
