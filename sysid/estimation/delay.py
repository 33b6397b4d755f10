"""Pure-delay (latency) estimate of a sound path from its noise recording.

Converter latency and the acoustic path put d samples of pure delay in front of the
plant. A rational model of modest order imitates d samples of delay only with many
poles, so the delay is estimated first and the core is fitted on delay-compensated
data (design.md, identification step 6).

Method: the H1 estimate S_yu / S_uu of the noise recording (Welch, ``spectra``) is
weighted by a raised-cosine taper cos^2(pi f / 2 f_top) up to f_top, the highest
frequency where the (9-bin averaged) squared coherence stays above 0.5, and inverted
by the inverse DFT. The result is the impulse response seen through a smooth
low-pass kernel (Oppenheim & Schafer, "Discrete-Time Signal Processing", 3rd ed.,
sec. 7.5 on window tapers). The onset is the first sample whose magnitude exceeds
both 10 % of the peak and six times the RMS of the response at negative times (noise
and circular wrap-around of long modes).

The kernel starts rising a few samples before the response it smooths, so the onset
is seldom later than the first non-zero sample of the true impulse response (only where
the response rises so slowly that its first samples stay below 10 % of the peak); the core
behind the delay has no direct term and adds one sample of its own, so the delay is
the onset less one: it errs short by the kernel's lead plus one, 1 to 4 samples on
most random helmets (long by 1 to 4 on 5 of 100, whose response rises slowly, see below).
Short is the safe side: a delay estimated too long asks the core for a non-causal
response it cannot give, one too short only asks for a little more order.

The kernel's lead is a resolution limit of any threshold on a band-limited response, so
the onset is then refined by the model (``refine_delay``): the core fitted behind the
short delay d0 imitates the missing k samples with some of its poles. With those poles
held fixed, the output-error cost V(d0 + j) (one linear least-squares solve, McKelvey's
frequency-domain model with the block's transient, ``output_error.linear_cost``) stays at
the noise level for every j up to k (the poles hold the true ones and spare ones, and
any strictly proper response with those poles is reachable by the numerator) and rises
once j > k asks the core for a response before its first sample. The delay is the
largest d0 + j whose cost is within 40 / (2 M) of the smallest (M bins; 2 M real
residuals). The cost of the poles of the order search's short block wanders by up to
0.3 % between delays the core can hold (its spare poles imitate the missing samples only
roughly), while a delay one sample too long raises it by 3 % to 20x on the random helmets
whose first sample is not small; where it is small (two roll-off poles: the response
rises as t^2), one or two samples too long cost less than 0.2 % and change the model by
as little. The search goes up to 4 samples past d0 (the largest lead on most random
helmets), and further, 4 samples at a time up to 12, while the cost at the window's last
sample is still at the minimum and below the cost at d0: the lead reached 10 to 14 samples
on random helmet 30 (a sixth-order core whose cost falls by 1 % over j = 0..11 and rises
after). A window of 12 from the start read a smoothly starting plant (random helmet 7, two
roll-off poles) 2 samples long instead of 1: its cost grows by 0.01-0.04 % a sample, within
the tolerance. ``identify`` keeps a moved delay only if a refit behind it validates on the
sweeps as well as the model before it.

Two cases the fixed poles cannot decide, where they are refitted at each candidate delay
(output error from the same poles, 10 iterations on the same block) and the refitted costs
decide, by the same rule (the largest delay within the tolerance of the smallest):
- A cost that falls again after rising past the answer (by more than the tolerance, to
  within 10 % of the smallest). Too long a delay costs more the longer it is (the core loses
  more of its response's first samples); a dip says the spare poles imitate that many
  missing samples better than fewer, but only roughly. Random helmet 49 (short session):
  a 9-state core for a 7-state plant 3 samples short, fixed-pole costs 1, 1.041, 1.022,
  1.021, 1.65 at j = 0..4, refitted 1.003, -, 1.001, 1 at j = 0, 2, 3: the true delay.
- The onset read long (a slowly rising response crosses 10 % of its peak late: random
  helmet 94, two modes of Q 0.9 and 2.9 near 1.2-1.7 kHz behind a roll-off, onset 4 samples
  late; or modes that outlast the Welch segment wrap around into the negative times and raise
  the threshold: random helmet 100 FF, Q 7-30 at 49-113 Hz, onset 6-9 samples late). A core
  behind too long a delay cannot be causal, so the window extends ``max_extra`` samples below
  d0 (never below a total delay of zero), and further, ``max_extra`` at a time up to ``widest``,
  while its first cost is the smallest and below V(d0) by more than the tolerance; when the
  fixed-pole cost there falls below V(d0) by more than the tolerance, the refitted costs at
  j <= 0 decide, by their smallest (not the largest delay within the tolerance: read long, the
  core has no spare poles, and the longer delays within the tolerance are the first samples
  of a slowly starting response; short is the safe side). 94: 1, 1, 1.002, 1.037, 1.38 at
  j = -4..0.

The ear signal's spectral lines that the input lacks (mains hum, an engine order) are fitted
and taken out of the recording first (``without_residual_lines``): no delay fits them, and left in
they are most of the cost, which makes the relative tolerance span far more than the noise.
``identify`` takes the session's lines out before the order search (``sysid.io.lines``); what it
hands over here holds only lines too weak to be found there. Random helmet 102 FF with an
engine order (41.7 Hz, 5.4e-4 FS, beside 9.2e-4 FS of sensor noise) and a pure delay: with the
lines left in the recordings identify fits, the delay read 28 for 27 (one sample past within
the tolerance, 0.28 % against 0.4 %, at the poles of a core fitted on hummed data); with the
repeats' two lines out but the third harmonic (1.8e-4 FS, missed in the 2 s repeats) left in,
23 (the move to 27 rejected on the sweeps); with all three out (the third found in the noise
recording), 27. At the final model's poles every one of these recordings reads 27.

The delay is decided in one place, ``decide_delay`` (``refine_delay``, then ``walk_delay`` when not read
long), by ``identify`` after its order search and by ``refits`` after a data correction. Where the refitted
costs cannot tell two delays apart it errs short: a core behind a delay a sample too short imitates the sample
nearly free, one behind a delay too long cannot be causal and imitates a lead with poles run to z = -1 and
residues that cancel in band, invisible in the cost and tens of times the floor in simulation (random helmet 41,
short, delay 11 for 10: 10.9x). Poles at the block's radius bound are such imitators, and the delays are compared
from starts without them too (``_causal_start``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core import lti
from ..io.lines import find_lines, fit_sinusoids
from ..io.recordings import Recording
from .order_search import distinct_start
from .output_error import block_data, linear_cost, radius_bound_mask, refine_output_error
from .spectra import Spectra

__all__ = ["LatencyEstimate", "estimate_latency", "refine_delay", "walk_delay", "decide_delay", "DelayWalk",
           "compensate_delay", "SPEED_OF_SOUND", "delay_centimetres"]

SPEED_OF_SOUND = 343.0  # m/s in air at 20 degrees C
_COHERENCE_LIMIT = 0.5
_PEAK_FRACTION = 0.1
_NOISE_MULTIPLE = 6.0
# refine_delay: a cost dip past the answer is refitted when within this fraction of the smallest cost;
# output-error iterations of each refit (a start near the answer converges in a few).
_PLAUSIBLE = 0.10
_REFIT_ITERATIONS = 10
# walk_delay: samples it may move from refine_delay's answer (further when the band's kernel lead is longer).
_WALK_SPAN = 12
# walk_delay walks up until a cost rises this many output-noise variances sigma^2 = V / (2 M) (M bins) above the
# smallest (past the true delay the cost rises by 3 % to 20x a sample where the response's first sample is not small,
# thousands of sigma^2), and refits again from the best core's poles the delays within it.
_WALK_CLEAR = 20.0
# walk_delay's decision (``_decided``): up from the smallest cost through costs within this many sigma^2 of it.
_WALK_STEP = 2.0


def delay_centimetres(samples: float, fs: float) -> float:
    """Sound-path length (cm) travelled in ``samples`` samples at fs Hz (0.78 cm per sample at 44.1 kHz)."""
    return 100.0 * SPEED_OF_SOUND * samples / fs


@dataclass(frozen=True)
class LatencyEstimate:
    """The estimated pure delay (samples), how it was found, and the impulse response (FS per FS, per sample)."""

    samples: int
    fs: float
    onset: int
    top_hz: float
    threshold: float
    impulse_response: np.ndarray
    # Samples added by ``refine_delay`` to the onset's estimate (None: not refined).
    refined_by: int | None = None

    @property
    def centimetres(self) -> float:
        return delay_centimetres(self.samples, self.fs)

    def to_dict(self) -> dict:
        method = "onset of the band-limited H1 impulse response"
        if self.refined_by is not None:
            method += f", refined by {self.refined_by} sample(s) by the output-error cost at the model's poles"
        return {"samples": self.samples, "centimetres": round(self.centimetres, 2), "top_hz": round(self.top_hz, 1),
                "method": method}


def estimate_latency(spectra: Spectra, max_delay: int | None = None) -> LatencyEstimate:
    """Pure delay of the path from unsmoothed Welch spectra (see the module docstring).

    ``max_delay`` (samples) bounds the search; by default a quarter of the segment length.
    """
    n = spectra.nperseg
    f = spectra.frequencies
    with np.errstate(divide="ignore", invalid="ignore"):
        h1 = np.where(spectra.s_uu > 0, spectra.s_yu / spectra.s_uu, 0.0)
        coherence = np.nan_to_num(np.abs(spectra.s_yu) ** 2 / (spectra.s_uu * spectra.s_yy))
    smoothed = np.convolve(coherence, np.ones(9) / 9, mode="same")
    good = np.flatnonzero(smoothed > _COHERENCE_LIMIT)
    top = float(f[good[-1]]) if good.size else float(f[-1])
    top = min(max(top, 10 * f[1]), 0.45 * spectra.fs)
    taper = np.where(f <= top, np.cos(0.5 * np.pi * f / top) ** 2, 0.0)
    h = np.fft.irfft(h1 * taper, n)
    limit = n // 4 if max_delay is None else min(int(max_delay) + 1, n // 2)
    # Negative times (the second half of the circular response) hold only noise and wrap-around.
    negative = h[n // 2: n - 16]
    noise = float(np.sqrt(np.mean(negative**2))) if negative.size else 0.0
    causal = h[: n // 2]
    threshold = max(_PEAK_FRACTION * float(np.max(np.abs(causal))), _NOISE_MULTIPLE * noise)
    above = np.flatnonzero(np.abs(causal[:limit]) > threshold)
    # The smoothing kernel puts the onset zero to three samples before the true response's
    # first non-zero sample, index d + 1 for a delay d and a core without direct term (zero
    # when that first sample is large, as for the seed's FB plant). The core adds one sample
    # itself, so the delay line holds onset - 1 samples: short by the kernel's lead, never long.
    onset = int(above[0]) if above.size else 0
    samples = max(onset - 1, 0)
    return LatencyEstimate(samples, spectra.fs, onset, top, threshold, causal.copy())


def compensate_delay(recording: Recording, samples: int) -> Recording:
    """The recording with its ear signal advanced by ``samples``: u[t] against y[t + samples].

    A negative ``samples`` delays the ear signal instead (u[t - samples] against y[t]): a
    delay read too long is shortened this way.
    """
    if samples == 0:
        return recording
    if samples > 0:
        n = recording.u.size - samples
        u, y = recording.u[:n], recording.y[samples:]
    else:
        n = recording.u.size + samples
        u, y = recording.u[-samples:], recording.y[:n]
    return Recording(u, y, recording.fs, recording.path, recording.clipped_fraction, recording.dc_offset)


def without_residual_lines(noise: Recording, band: tuple[float, float], A=None, seconds: float = 1.0,
                  feedthrough: bool = False) -> Recording:
    """``noise`` with the ear signal's spectral lines that the input lacks fitted and taken out
    (``lines.find_lines``, ``lines.fit_sinusoids``): the recording itself when it
    has none. With a core's poles eig(A) (fitted on ``noise``), the lines are looked for in what the
    core leaves of the ear signal (its linear step on the first ``seconds``, simulated on the whole
    recording), where the plant's response to the input no longer hides them.

    Mains hum or an engine order is no response to the input, and no delay fits it: left in, it
    is most of the cost V (random helmet 100 FF with 41.7 Hz and harmonics at 1e-3 FS against
    1.1e-4 FS of sensor noise: about 500 times the noise in the band), so the tolerance
    40 / (2 M) of V spans costs that differ by twice the whole noise, and a delay 4 samples past
    the answer was read as within it.
    """
    left = noise.y
    if A is not None:
        n = A.shape[0]
        core = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)),
                                   block_data(noise, band, seconds), feedthrough=feedthrough, max_iterations=1)
        left = noise.y - lti.simulate(core.A, core.B, core.C, core.D, noise.u)
    # The whole recording: a line grows with its length against the noise around it.
    lines = [line[0] for line in find_lines(left, noise.u, noise.fs, band)]
    if not lines:
        return noise
    return Recording(noise.u, noise.y - fit_sinusoids(left, lines, noise.fs), noise.fs, noise.path,
                     noise.clipped_fraction, noise.dc_offset)


def _causal_start(A, data, feedthrough: bool) -> np.ndarray:
    """A with its poles at the block's radius bound replaced (``order_search.distinct_start``), as given when
    it has none.

    A core behind too long a delay imitates the lead it cannot have with poles run to z = -1 and residues that
    cancel in band (random helmet 41, short session: 8 modes right and a real pole at -0.99998 behind a delay
    read 12 for the true 10). Held fixed, or refitted from there behind a shorter delay, those poles stay where
    the longer delay put them: refitted from them for 10 iterations the cost at the true delay was 2.7 times the
    one at 11; from the same poles with the bound one replaced, 0.56 times (and 1.0 at 9).
    """
    A = np.asarray(A, dtype=float)
    poles = np.linalg.eigvals(A)
    if not radius_bound_mask(poles, data).any():
        return A
    return lti.real_block_diagonal(distinct_start(poles, data, feedthrough))


def refine_delay(A, noise: Recording, band: tuple[float, float], seconds: float, max_extra: int = 4,
                 feedthrough: bool = False, widest: int = 12, delay: int = 0,
                 lines_out: bool = False) -> tuple[int, np.ndarray]:
    """Samples j to add to the delay and the costs that decided it (``_refine_delay``; see there)."""
    extra, costs, _ = _refine_delay(A, noise, band, seconds, max_extra, feedthrough, widest, delay, lines_out)
    return extra, costs


def _refine_delay(A, noise: Recording, band: tuple[float, float], seconds: float, max_extra: int = 4,
                  feedthrough: bool = False, widest: int = 12, delay: int = 0,
                  lines_out: bool = False) -> tuple[int, np.ndarray, dict]:
    """Samples j in -widest..widest to add to the delay of a core with poles eig(A) fitted on
    ``noise`` (already advanced by the current delay), and the costs V of the window that decided
    it, lowest j first (from j = 0 unless the delay was shortened); see the module docstring.
    ``seconds`` of the recording are used (``output_error.block_data``).

    ``delay`` is the delay already taken out of ``noise``: the window goes down to
    j = -min(max_extra, delay) (a total delay below zero is not a delay). Fixed-pole costs V(j)
    over -min(max_extra, delay)..max_extra first. While the cost at the window's last
    sample is within the tolerance of the smallest and below the cost at j = 0, the window grows
    by ``max_extra`` up to ``widest`` samples. When the cost at some j < 0 is below V(0) by more than
    the tolerance (the onset read long), or a delay past the answer costs less than a shorter one
    past it (a dip, within _PLAUSIBLE of the smallest: the spare poles imitate the missing samples
    only roughly), the poles are refitted at j <= 0, or at the answer and the dips
    (``output_error.refine_output_error``, _REFIT_ITERATIONS), and the refitted costs decide
    (infinite where not refitted). ``lines_out``: ``noise`` is already ``without_residual_lines``'s.
    Each cost is the lower of the poles as given and with those at the block's radius bound replaced
    (``_causal_start``). Also returns the refitted cores (j -> ``output_error.OutputErrorFit``; empty when none
    was refitted).
    """
    if not lines_out:
        noise = without_residual_lines(noise, band, A, seconds, feedthrough)
    A = np.asarray(A, dtype=float)
    # The poles as given and, where some sit at the radius bound, with those replaced: each delay's cost is the
    # lower of the two (random helmet 41 asks for the replacement; 94, short, n 6 for a 6-state plant read 4
    # long, refits better from its own poles: 1.097 against 1 at the true delay from the replacement's).
    starts = [A] + [B for B in [_causal_start(A, block_data(noise, band, seconds), feedthrough)] if B is not A]

    def block(j):
        return block_data(compensate_delay(noise, j), band, seconds)

    def cost(j):
        data = block(j)
        return min(linear_cost(B, data, feedthrough=feedthrough) for B in starts)

    tolerance = 1 + 40.0 / (2 * block(0).z.size)
    zero = min(max_extra, max(int(delay), 0))  # index of j = 0: the delay never goes below zero
    costs = [cost(j) for j in range(-zero, max_extra + 1)]
    while costs[-1] <= min(costs) * tolerance and costs[-1] < costs[zero] and len(costs) - 1 - zero < widest:
        last = len(costs) - 1 - zero
        costs += [cost(j) for j in range(last + 1, min(last + 1 + max_extra, widest) + 1)]
    # Read long, the window grows downwards alike while its first cost is the smallest and clearly
    # below V(0) (random helmet 100 FF, its onset 7 samples late: the cost still falls at j = -4).
    while 0 < zero < min(int(delay), widest) and costs[0] <= min(costs) and costs[0] * tolerance < costs[zero]:
        lower = min(zero + max_extra, int(delay), widest)
        costs = [cost(j) for j in range(-lower, -zero)] + costs
        zero = lower
    costs = np.array(costs)
    shifts = np.arange(costs.size) - zero
    read_long = bool(zero) and costs[:zero].min() * tolerance < costs[zero]
    if read_long:
        # Samples before the core's first one carry response: the onset was read long.
        refit_at = shifts[: zero + 1]
    else:
        costs, shifts = costs[zero:], shifts[zero:]
        extra = int(shifts[np.flatnonzero(costs <= costs.min() * tolerance)[-1]])
        # Past the answer a too-long delay costs more the longer it is (the core loses more of its
        # response's first samples); a cost that falls again after rising is the spare poles
        # imitating that many missing samples better than fewer.
        rising = np.maximum.accumulate(np.where(shifts >= extra, costs, 0.0))
        dips = (shifts > extra) & (costs * tolerance < rising) & (costs <= costs.min() * (1 + _PLAUSIBLE))
        if not dips.any():
            return extra, costs, {}
        refit_at = shifts[dips | (shifts == extra)]
    # Held fixed, the poles cannot tell: refitted, the spare ones take up what the delay line leaves.
    n = A.shape[0]
    refit = np.full(costs.size, np.inf)
    fits = {}
    for j in refit_at:
        data = block(j)
        fits[int(j)] = min((refine_output_error(B, np.zeros((B.shape[0], 1)), np.zeros((1, B.shape[0])),
                                                np.zeros((1, 1)), data, feedthrough=feedthrough,
                                                max_iterations=_REFIT_ITERATIONS) for B in starts),
                           key=lambda fit: fit.cost_after)
        refit[j - shifts[0]] = fits[int(j)].cost_after
    if read_long:
        # Read long, the core behind the onset had no spare poles: the refitted cost is smallest where
        # the core is causal again, and the longer delays within the tolerance are a slowly starting
        # response's first samples, too small to tell from delay (random helmet 100 FF, pure delay 34
        # behind roll-offs worth 3.7 samples: the true poles refitted cost within the tolerance over
        # total delays 31-38); short is the safe side, so the shortest delay within the tolerance of the
        # smallest cost. The smallest cost itself is a draw of the noise among costs that flat (random
        # helmet 100 FF with a pure delay of 16 and an engine order: refitted 1.0003, 1, 1, 1.0007, 1.0042
        # at j = -4..0 from an onset 7 samples long, the smallest at -2 read 25 where at most 24 holds
        # the plant's delay and roll-offs).
        return int(shifts[np.flatnonzero(refit <= refit.min() * tolerance)[0]]), refit, fits
    return int(shifts[np.flatnonzero(refit <= refit.min() * tolerance)[-1]]), refit, fits


@dataclass(frozen=True)
class DelayWalk:
    """What ``walk_delay`` found: samples to add to the delay, the refitted core's poles there (A, real
    block diagonal or balanced), the refitted cost V at each delay it visited (samples -> cost) and the
    refitted cores (samples -> ``output_error.OutputErrorFit``)."""

    extra: int
    A: np.ndarray
    costs: dict[int, float]
    fits: dict = field(default_factory=dict)


def walk_delay(A, noise: Recording, band: tuple[float, float], seconds: float, start: int, feedthrough: bool = False,
               lead: int = 0, long_seconds: float | None = None, cleaned: Recording | None = None,
               refit_again: bool = True) -> DelayWalk:
    """The delay d >= 0 (samples added to the one taken out of ``noise``) whose core, refitted, holds the
    delay: up from the smallest refitted cost through costs within _WALK_STEP noise variances of it
    (``_decided``), found by walking one sample at a time from
    ``start`` (``refine_delay``'s answer) up and down to at most max(_WALK_SPAN, ``lead``) samples either side
    (``lead``: the band-limited kernel's lead, fs / (2 f_top) samples, how far short the onset may read);
    where that lead is longer than _WALK_SPAN, the walk is done again on ``long_seconds`` from its answer.
    ``cleaned``: ``without_residual_lines(noise, band, A, seconds, feedthrough)`` when already at hand.

    At each delay the poles are refitted (``output_error.refine_output_error``, _REFIT_ITERATIONS, stopped at
    the noise's tolerance) from those of the neighbouring delay: a continuation, so each refit starts one
    sample from its answer. Upwards the walk goes on until the cost rises _WALK_CLEAR sigma^2 above the
    smallest so far, downwards while the cost still falls; then the delays within _WALK_CLEAR of the smallest
    are refitted once more from the best core's poles (the walk's far end has had more iterations), unless
    ``refit_again`` is false or a longer block decides next.
    It starts from the better of the poles as given and with those at the block's radius bound replaced
    (``_causal_start``).

    Why up from the smallest: the data fix the in-band response H = z^-d G, and a shorter delay line leaves the core
    G to imitate the missing samples by an all-pass-like lag (zeros outside the unit circle, Pade-like),
    which a core with spare poles does within the noise over a band-limited recording. A longer delay than
    the true one asks the core for a lead no causal, stable core has (its phase lags the minimum phase of
    its magnitude: Oppenheim & Schafer, 3rd ed., sec. 5.6), and it loses the response's first samples, so
    its cost rises. The longest delay whose cost stays within the noise is the core with the least excess
    phase, the pure delay; where the rise past it is within the noise too (a smooth start), shorter is the safe
    side (``_decided``). A core with zeros of its own outside the unit circle (residues of either sign) keeps them:
    their lag starts at the response's first sample, which a longer delay line would cut.

    Held fixed, the picked core's poles cannot show this when they imitate the missing samples together
    with the dynamics (random helmet 51, short session: a 20-state core 3 samples short cost 1.39x at
    one sample more; refitted, the costs at 3 samples more were 0.3 % lower and rose by 3 % at 4), and a
    tolerance on fixed-pole costs that are flat to the last sample reads the largest of them (77: 3 samples
    long with a fixed-pole cost at 1.0038 against the tolerance 1.004; refitted, that delay costs 1.0078).
    A response that starts smoothly (roll-offs) is read long by part of their lag, fs / (2 pi f_c) samples
    each, by any tolerance larger than a sample's cost there (a sigma^2 or two).
    """
    if cleaned is None:
        cleaned = without_residual_lines(noise, band, A, seconds, feedthrough)
    bins = 2 * block_data(noise, band, seconds).z.size
    clear = 1 + _WALK_CLEAR / bins

    def refit(A0, j, recording=None):
        n = A0.shape[0]
        return refine_output_error(A0, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)),
                                   block_data(compensate_delay(recording or noise, j), band, seconds),
                                   feedthrough=feedthrough, max_iterations=_REFIT_ITERATIONS, noise_tolerance=True)

    start, span = max(int(start), 0), max(_WALK_SPAN, int(lead))
    A = np.asarray(A, dtype=float)
    fits = {start: refit(A, start)}
    causal = _causal_start(A, block_data(compensate_delay(noise, start), band, seconds), feedthrough)
    if causal is not A:
        # The walk goes on from the better of the poles as given and with those at the radius bound replaced.
        other = refit(causal, start)
        if other.cost_after < fits[start].cost_after:
            A, fits = causal, {start: other}
    if cleaned is not noise:
        # Lines taken out lower a refitted core's cost when they are a hum; a lightly damped mode the core's
        # one linear step misfits is found as lines too (random helmet 9, thesis length: three at 30.7-31.1 Hz
        # beside its 31 Hz mode of Q 20), and taken out it leaves data no core fits (refitted cost 30 times the
        # recording's own, every delay then read from a degenerate fit, delay -3; now +0). The recording that
        # fits better is walked.
        other = refit(A, start, cleaned)
        if other.cost_after < fits[start].cost_after:
            noise, fits = cleaned, {start: other}

    def smallest():
        return min(f.cost_after for f in fits.values())

    # Up until the cost rises clearly above the smallest so far (a refit one sample on may sit a few sigma^2
    # above its neighbours and the next ones fall again: random helmet 51, slow test's grid, a 20-state core 3
    # samples short, refitted 21 -> 22 rose by 7 sigma^2, and 24, the true delay, was 28 below 21); down while
    # the cost still falls.
    j = start
    while j < start + span:
        j += 1
        fits[j] = refit(fits[j - 1].A, j)
        if fits[j].cost_after > smallest() * clear:
            break
    j = start
    while j > max(start - span, 0):
        j -= 1
        fits[j] = refit(fits[j + 1].A, j)
        if fits[j].cost_after >= fits[j + 1].cost_after:
            break
    # Each refit of the walk starts from its neighbour's answer, so the fits further along have had more
    # iterations: the walk's far end reads lower than the delays it passed (random helmet 57, thesis length: 10
    # sigma^2 between 61-64 and 66, which refitted alike from the picked core differ by less than 1). Every
    # delay that could decide is refitted again from the best core's poles, and the lower cost kept.
    # Not where a longer block decides next, nor on that block (10 s refits: 1.3 s more on random helmet 30, thesis
    # length, whose costs there are flat within 0.5 sigma^2 without it).
    longer = lead > _WALK_SPAN and long_seconds is not None and long_seconds > seconds
    best = min(fits, key=lambda k: fits[k].cost_after)
    for k in sorted(fits) if refit_again and not longer else []:
        if k != best and fits[k].cost_after <= smallest() * clear:
            again = refit(fits[best].A, k)
            if again.cost_after < fits[k].cost_after:
                fits[k] = again
    costs = {k: f.cost_after for k, f in sorted(fits.items())}
    extra = _decided(costs, bins)
    if longer:
        # A narrow coherent band (the kernel's lead past the span): the scan block's bins above it are noise, the
        # refitted costs there wander by as much as a few samples of delay cost, and ``long_seconds`` decide from
        # the scan block's answer (random helmet 30, thesis length, band to 360 Hz: the 1 s block read 21 or 29
        # for 25 by the tolerance; on 10 s the costs are flat to 26 within 0.5 sigma^2 and 60 sigma^2 up at 28).
        return walk_delay(fits[extra].A, noise, band, long_seconds, extra, feedthrough, cleaned=noise,
                          refit_again=False)
    return DelayWalk(extra, fits[extra].A, costs, fits)


def decide_delay(A, noise: Recording, band: tuple[float, float], seconds: float, delay: int = 0,
                 feedthrough: bool = False, lead: int = 0, long_seconds: float | None = None,
                 cleaned: Recording | None = None) -> DelayWalk:
    """Samples to add to the delay of a core with poles eig(A) fitted on ``noise`` (already advanced by the
    ``delay`` it was fitted behind), and the refitted cores that decided it: the one place the delay is decided
    (``identify`` after its order search, ``refits`` after a data correction).

    ``refine_delay`` first (fixed-pole costs, the window below the onset when it read long); read long
    (extra < 0), its refitted costs decided and its refits are returned; read short or right, ``walk_delay``
    settles it from there. ``cleaned``: ``without_residual_lines(noise, band, A, seconds, feedthrough)`` when
    already at hand. Costs are those of the refitted cores (j -> V).
    """
    if cleaned is None:
        cleaned = without_residual_lines(noise, band, A, seconds, feedthrough)
    extra, costs, fits = _refine_delay(A, cleaned, band, seconds, feedthrough=feedthrough, delay=delay,
                                       lines_out=True)
    if extra < 0:
        return DelayWalk(extra, fits[extra].A, {j: f.cost_after for j, f in sorted(fits.items())}, fits)
    return walk_delay(A, noise, band, seconds, extra, feedthrough, lead, long_seconds, cleaned)


def _decided(costs: dict[int, float], bins: int) -> int:
    """The delay (samples -> refitted cost V) the walk settles on: from the smallest cost, up through the
    delays whose cost stays within _WALK_STEP noise variances sigma^2 = V / ``bins`` (real residuals) of it,
    one sample at a time; the last of them.

    Below the true delay a core with spare poles imitates the missing samples nearly free, so the costs
    there are flat and the smallest may fall a sample or two short; past it a core loses the response's first
    samples and the cost rises, by 3 % to 20x a sample where the first sample is not small, by only a sigma^2
    or two a sample where the response starts smoothly (roll-offs: it starts as t^2), where the costs cannot
    tell a longer delay from the true one. Taking the largest delay within 5 sigma^2 of the smallest read
    those long (random helmet 57, thesis length, two roll-offs at 5.1 and 5.7 kHz, true 62: 10.6, 0, 8.9, 4.5,
    0.9, 0.2, 24 sigma^2 at 61-67, read 66; 17, short: 3.3, 0, 1.3, 2.1, 113 at 17-21, true 17, read 20); through
    costs within 2 sigma^2 it errs short instead (62 and 19). One sigma^2 (what a parameter fitted to noise alone
    gains) is below what the walk's refits differ by between delays a core holds alike (helmet 4, short: 0, 1.3,
    0.8, 0.7, 4.2 sigma^2 at 11-15, true 14, read 11 through one). Over the walks of the 100 short random helmets
    the decision's error is -1..+2 but for 57 (short: 1.9, 0, 1.1, 1.4, 7.9 at 63-67, +4); the largest within
    5 sigma^2: -1..+4 (17 and 57 beyond 2).
    """
    smallest = min(costs, key=costs.get)
    limit = costs[smallest] * (1 + _WALK_STEP / bins)
    j = smallest
    while j + 1 in costs and costs[j + 1] <= limit:
        j += 1
    return j
