"""The delay decided: the core refitted one sample of delay at a time (``walk_delay``, ``decide_delay``).

``decide_delay`` is the one decision, by ``identify`` after its order search
(``sysid.estimation.delay.trials.moved_delay``) and by ``refits`` after a data correction:
``refine_delay`` first (``sysid.estimation.delay.costs``: fixed-pole costs, the window below
the onset when it read long), then ``walk_delay`` when not read long. Where the refitted costs
cannot tell two delays apart it errs short: a core behind a delay a sample too short imitates the
sample nearly free, one behind a delay too long cannot be causal and imitates a lead with poles run
to z = -1 and residues that cancel in band, invisible in the cost and tens of times the floor in
simulation (random helmet 41, short, delay 11 for 10: 10.9x). Poles at the block's radius bound
are such imitators, and the delays are compared from starts without them too (``_causal_start``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...core.thresholds import DELAY_REFIT_ITERATIONS, WALK_CLEAR, WALK_SPAN, WALK_STEP
from ...io.recordings import Recording
from ..output_error import block_data, refine_output_error
from .costs import _causal_start, _refine_delay, without_residual_lines
from .onset import compensate_delay

__all__ = ["DelayWalk", "walk_delay", "decide_delay"]


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
    delay: up from the smallest refitted cost through costs within WALK_STEP noise variances of it
    (``_decided``), found by walking one sample at a time from
    ``start`` (``refine_delay``'s answer) up and down to at most max(WALK_SPAN, ``lead``) samples either side
    (``lead``: the band-limited kernel's lead, fs / (2 f_top) samples, how far short the onset may read);
    where that lead is longer than WALK_SPAN, the walk is done again on ``long_seconds`` from its answer.
    ``cleaned``: ``without_residual_lines(noise, band, A, seconds, feedthrough)`` when already at hand.

    At each delay the poles are refitted (``output_error.refine_output_error``, DELAY_REFIT_ITERATIONS, stopped at
    the noise's tolerance) from those of the neighbouring delay: a continuation, so each refit starts one
    sample from its answer. Upwards the walk goes on until the cost rises WALK_CLEAR sigma^2 above the
    smallest so far, downwards while the cost still falls; then the delays within WALK_CLEAR of the smallest
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
    clear = 1 + WALK_CLEAR / bins

    def refit(A0, j, recording=None):
        n = A0.shape[0]
        return refine_output_error(A0, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)),
                                   block_data(compensate_delay(recording or noise, j), band, seconds),
                                   feedthrough=feedthrough, max_iterations=DELAY_REFIT_ITERATIONS, noise_tolerance=True)

    start, span = max(int(start), 0), max(WALK_SPAN, int(lead))
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
    longer = lead > WALK_SPAN and long_seconds is not None and long_seconds > seconds
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
    delays whose cost stays within WALK_STEP noise variances sigma^2 = V / ``bins`` (real residuals) of it,
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
    limit = costs[smallest] * (1 + WALK_STEP / bins)
    j = smallest
    while j + 1 in costs and costs[j + 1] <= limit:
        j += 1
    return j
