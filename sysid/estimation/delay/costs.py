"""The delay read from the output-error cost at a core's poles: the fixed-pole costs and the detector's scan.

The onset's delay errs short by the band-limited kernel's lead (``sysid.estimation.delay.onset``):
the core fitted behind the short delay d0 imitates the missing k samples with some of its poles.
With those poles held fixed, the output-error cost V(d0 + j) (one linear least-squares solve,
McKelvey's frequency-domain model with the block's transient, ``output_error.linear_cost``) stays at
the noise level for every j up to k (the poles hold the true ones and spare ones, and any strictly
proper response with those poles is reachable by the numerator) and rises once j > k asks the core
for a response before its first sample. ``refine_delay``: the delay is the largest d0 + j whose cost
is within ``DELAY_TOLERANCE`` / (2 M) of the smallest (M bins; 2 M real residuals). The cost of the
poles of the order search's short block wanders by up to 0.3 % between delays the core can hold (its
spare poles imitate the missing samples only roughly), while a delay one sample too long raises it by
3 % to 20x on the random helmets whose first sample is not small; where it is small (two roll-off
poles: the response rises as t^2), one or two samples too long cost less than 0.2 % and change the
model by as little. The search goes up to ``DELAY_WINDOW`` samples past d0 (the largest lead on most
random helmets), and further, as many at a time up to ``DELAY_WIDEST``, while the cost at the window's
last sample is still at the minimum and below the cost at d0: the lead reached 10 to 14 samples on
random helmet 30 (a sixth-order core whose cost falls by 1 % over j = 0..11 and rises after). A window
of 12 from the start read a smoothly starting plant (random helmet 7, two roll-off poles) 2 samples
long instead of 1: its cost grows by 0.01-0.04 % a sample, within the tolerance.

Two cases the fixed poles cannot decide, where they are refitted at each candidate delay (output
error from the same poles, ``DELAY_REFIT_ITERATIONS`` on the same block) and the refitted costs
decide, by the same rule (the largest delay within the tolerance of the smallest):

- A cost that falls again after rising past the answer (by more than the tolerance, to within
  ``DELAY_DIP`` of the smallest). Too long a delay costs more the longer it is (the core loses more
  of its response's first samples); a dip says the spare poles imitate that many missing samples
  better than fewer, but only roughly. Random helmet 49 (short session): a 9-state core for a
  7-state plant 3 samples short, fixed-pole costs 1, 1.041, 1.022, 1.021, 1.65 at j = 0..4,
  refitted 1.003, -, 1.001, 1 at j = 0, 2, 3: the true delay.
- The onset read long (a slowly rising response crosses 10 % of its peak late: random helmet 94,
  two modes of Q 0.9 and 2.9 near 1.2-1.7 kHz behind a roll-off, onset 4 samples late; or modes
  that outlast the Welch segment wrap around into the negative times and raise the threshold:
  random helmet 100 FF, Q 7-30 at 49-113 Hz, onset 6-9 samples late). A core behind too long a
  delay cannot be causal, so the window extends ``max_extra`` samples below d0 (never below a total
  delay of zero), and further, ``max_extra`` at a time up to ``widest``, while its first cost is the
  smallest and below V(d0) by more than the tolerance; when the fixed-pole cost there falls below
  V(d0) by more than the tolerance, the refitted costs at j <= 0 decide, by their smallest (not the
  largest delay within the tolerance: read long, the core has no spare poles, and the longer delays
  within the tolerance are the first samples of a slowly starting response; short is the safe
  side). 94: 1, 1, 1.002, 1.037, 1.38 at j = -4..0.

The ear signal's spectral lines that the input lacks (mains hum, an engine order) are fitted and
taken out of the recording first (``without_residual_lines``): no delay fits them, and left in they
are most of the cost, which makes the relative tolerance span far more than the noise. ``identify``
takes the session's lines out before the order search (``sysid.io.lines``); what it hands over here
holds only lines too weak to be found there. Random helmet 102 FF with an engine order (41.7 Hz,
5.4e-4 FS, beside 9.2e-4 FS of sensor noise) and a pure delay: with the lines left in the recordings
identify fits, the delay read 28 for 27 (one sample past within the tolerance, 0.28 % against 0.4 %,
at the poles of a core fitted on hummed data); with the repeats' two lines out but the third harmonic
(1.8e-4 FS, missed in the 2 s repeats) left in, 23 (the move to 27 rejected on the sweeps); with all
three out (the third found in the noise recording), 27. At the final model's poles every one of
these recordings reads 27.

The delay detector (``sysid.findings.delay``) scans the same cost over total delays 0 up to
``MAX_EXTRA_DELAY`` past the model's own, at the model's poles (``fixed_pole_scan``) or at a generic
pole set that holds no delay (``generic_pole_scan``).
"""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from ...core import lti
from ...core.thresholds import (DELAY_DIP, DELAY_REFIT_ITERATIONS, DELAY_TOLERANCE, DELAY_WIDEST, DELAY_WINDOW,
                                MAX_EXTRA_DELAY)
from ...io.lines import find_lines, fit_sinusoids
from ...io.recordings import Recording
from ..order_search import distinct_start
from ..output_error import BlockData, block_data, linear_cost, radius_bound_mask, refine_output_error
from .onset import compensate_delay

__all__ = ["refine_delay", "without_residual_lines", "fixed_pole_scan", "generic_pole_scan", "generic_poles",
           "generic_start"]


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
    DELAY_TOLERANCE / (2 M) of V spans costs that differ by twice the whole noise, and a delay 4 samples past
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


def refine_delay(A, noise: Recording, band: tuple[float, float], seconds: float, max_extra: int = DELAY_WINDOW,
                 feedthrough: bool = False, widest: int = DELAY_WIDEST, delay: int = 0,
                 lines_out: bool = False) -> tuple[int, np.ndarray]:
    """Samples j to add to the delay and the costs that decided it (``_refine_delay``; see there)."""
    extra, costs, _ = _refine_delay(A, noise, band, seconds, max_extra, feedthrough, widest, delay, lines_out)
    return extra, costs


def _refine_delay(A, noise: Recording, band: tuple[float, float], seconds: float, max_extra: int = DELAY_WINDOW,
                  feedthrough: bool = False, widest: int = DELAY_WIDEST, delay: int = 0,
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
    past it (a dip, within DELAY_DIP of the smallest: the spare poles imitate the missing samples
    only roughly), the poles are refitted at j <= 0, or at the answer and the dips
    (``output_error.refine_output_error``, DELAY_REFIT_ITERATIONS), and the refitted costs decide
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

    tolerance = 1 + DELAY_TOLERANCE / (2 * block(0).z.size)
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
        dips = (shifts > extra) & (costs * tolerance < rising) & (costs <= costs.min() * (1 + DELAY_DIP))
        if not dips.any():
            return extra, costs, {}
        refit_at = shifts[dips | (shifts == extra)]
    # Held fixed, the poles cannot tell: refitted, the spare ones take up what the delay line leaves.
    refit = np.full(costs.size, np.inf)
    fits = {}
    for j in refit_at:
        data = block(j)
        fits[int(j)] = min((refine_output_error(B, np.zeros((B.shape[0], 1)), np.zeros((1, B.shape[0])),
                                                np.zeros((1, 1)), data, feedthrough=feedthrough,
                                                max_iterations=DELAY_REFIT_ITERATIONS) for B in starts),
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



def fixed_pole_scan(A, data: BlockData, delay: int, max_extra: int = MAX_EXTRA_DELAY,
                    coarse: bool = False) -> tuple[int, np.ndarray]:
    """(best total delay, fixed-pole cost V per total delay 0..``delay`` + ``max_extra``) of the poles eig(A) on
    ``data`` (``output_error.linear_cost``: the zeros, gain and block transient fitted by linear least squares).

    ``coarse``: every second delay (and ``delay``, the model's own), then the neighbours of the best (as
    ``generic_pole_scan``); the delays not evaluated hold NaN. The cost falls over a few samples towards a
    missing delay, so the step of 2 still lands next to its minimum.
    """
    delays = np.arange(0, delay + max_extra + 1)
    costs = np.full(delays.size, np.nan)
    with threadpool_limits(limits=1, user_api="blas"):
        first = sorted(set(range(0, delays.size, 2)) | {delay}) if coarse else range(delays.size)
        for d in first:
            costs[d] = linear_cost(A, data, int(d))
        if coarse:
            centre = int(np.nanargmin(costs))
            for d in range(max(centre - 1, 0), min(centre + 2, delays.size)):
                if np.isnan(costs[d]):
                    costs[d] = linear_cost(A, data, int(d))
    return int(delays[np.nanargmin(costs)]), costs


def generic_poles(fs: float) -> np.ndarray:
    """The generic pole set (block-diagonal A, fs Hz): second-order modes with Q = 2 at 12 log-spaced
    frequencies from 30 Hz to 4.5 kHz and two slow real poles, a basis for any smooth path response."""
    f0 = np.geomspace(30.0, 4500.0, 12)
    upper = np.exp(-np.pi * f0 / (2.0 * fs)) * np.exp(2j * np.pi * f0 / fs)
    return lti.real_block_diagonal(np.concatenate([upper, np.conj(upper), [0.9, 0.99]]))


def generic_start(data: BlockData, fs: float, delay: int, order: int, feedthrough: bool = False):
    """(A, B, C, D): a starting model of ``order`` states behind ``delay`` samples that owes nothing to a
    fitted model's poles: the zeros of the generic poles (``generic_poles``) fitted to ``data`` by linear
    least squares, then balanced-truncated to ``order`` (None when no truncation holds its response)."""
    A = generic_poles(fs)
    n = A.shape[0]
    fit = refine_output_error(A, np.ones((n, 1)), lti.block_output_row(A), np.zeros((1, 1)), data, delay=delay,
                              feedthrough=feedthrough, max_iterations=1)
    truncated = lti.balanced_truncation(fit.A, fit.B, fit.C, fit.D, order=order)
    return None if truncated is None else truncated[:4]


def generic_pole_scan(data: BlockData, fs: float, delay: int, max_extra: int = MAX_EXTRA_DELAY) -> int:
    """Best total delay from ``delay`` to ``delay`` + ``max_extra`` with a fixed generic pole set (fs Hz).

    Second-order modes with Q = 2 at 12 log-spaced frequencies from 30 Hz to 4.5 kHz
    (and two slow real poles) describe any smooth path response but no delay, so the
    cost's minimum over d marks the delay even when a model's own poles, bent to
    mimic the delay, make the fixed-pole scan flat. Coarse steps of 2, then +-1.
    """
    A = generic_poles(fs)
    with threadpool_limits(limits=1, user_api="blas"):
        coarse = {d: linear_cost(A, data, d) for d in range(delay, delay + max_extra + 1, 2)}
        centre = min(coarse, key=coarse.get)
        fine = {d: coarse.get(d) or linear_cost(A, data, d) for d in range(max(centre - 1, delay), centre + 2)}
    return min(fine, key=fine.get)
