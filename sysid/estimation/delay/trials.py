"""The delay tried on the sweeps: a decided delay becomes a model's only when a core behind it validates.

``decide_delay`` reads the delay from the noise recording; the sweeps have the last word.

- ``moved_delay``, after ``identify``'s order search: the pick's core moved behind the decided
  delay, refitted from the pick's poles, from the walk's poles at that delay and from the
  neighbouring orders' (the samples now in the delay line free the poles that imitated them),
  kept when it validates as well as the pick. A trial the sweeps reject (a freed pole run
  toward z = 1 rings in the simulated sweeps: random helmet 2, short, one sample past the true
  delay at 84x) gives way to the next shorter delays the walk visited, up to ``DELAY_TRIES``.
- ``shorter_delays``, after a refit of ``refine``: the core identified anew behind delays up to
  ``SHORTER_BY`` samples shorter than the model's (the onset reads long on a slowly rising
  response), the re-identification given by the caller.
- ``delay_totals``: the total delays ``refine --add delay`` tries, the total and one less.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np

from ...core import lti
from ...core.model import Model
from ...core.thresholds import DELAY_TRIES, FREED_ORDERS, MOVED_HANKEL_GROWTH, SHORTER_BY
from ...io.recordings import Recording
from ...validation.sweeps import SweepSpectrum, sweep_spectrum
from ..order_search import OrderCandidate, sweep_rms, without_freed_pole
from ..output_error import at_radius_bound, block_data, refine_output_error
from .onset import compensate_delay
from .walk import decide_delay

__all__ = ["TrialOptions", "MovedDelay", "moved_delay", "no_lead", "fewest_states", "shorter_delays", "delay_totals"]


@dataclass(frozen=True)
class TrialOptions:
    """What the moved-delay trials read of ``identify``'s options: the identification band and the
    validation band (Hz), the scan block's and the long block's seconds, whether the core has a direct
    term, and the relative gain in validation rms that counts (``min_gain``)."""

    band: tuple[float, float]
    validation_band: tuple[float, float]
    scan_seconds: float
    long_seconds: float
    feedthrough: bool
    min_gain: float


@dataclass(frozen=True)
class MovedDelay:
    """What ``moved_delay`` settled: samples moved into the delay line (negative: moved out of it),
    the pick behind the new delay and its time-domain validation rms (FS), the noise block and the
    sweeps' spectra behind it."""

    extra: int
    pick: OrderCandidate
    rms: float
    body: Recording
    sweep_spectra: list[SweepSpectrum]


class _Start(NamedTuple):
    """A trial's start: poles still to drop, label, start model, reflected poles, grid gamma."""

    drops: int
    label: str
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    reflected: int
    gamma: int | None


def moved_delay(pick: OrderCandidate, pick_rms: float, candidates: list[OrderCandidate], body: Recording,
                sweeps: list[Recording], delay: int, validate: Callable[[OrderCandidate, int], float],
                options: TrialOptions, lead: int = 0) -> MovedDelay | None:
    """The pick behind the delay its core decides (``decide_delay``), when a core there validates as well.

    ``pick`` is the order search's pick among ``candidates``, fitted on ``body`` (the noise block advanced by
    ``delay``), ``pick_rms`` its validation rms by ``validate(candidate, total_delay)`` (simulated on the
    ``sweeps``: a pole the in-band fit leaves near z = 1 shows only there); ``lead``: the band-limited kernel's
    lead (``LatencyEstimate.lead``). None when the delay stays: decided where it is, or the sweeps reject every try.
    """
    # The onset errs short by the smoothing kernel's lead, or long on a slowly rising response; the
    # picked core's poles say by how much.
    # Read short (or right), the refitted costs settle it, walked one sample at a time from the fixed poles'
    # answer; read long, the refitted costs below the onset's delay (decide_delay, shared with refits).
    walked = decide_delay(pick.A, body, options.band, options.scan_seconds, delay, feedthrough=options.feedthrough,
                          lead=lead, long_seconds=options.long_seconds)
    extra = walked.extra
    # The walk's answer first; a trial the sweeps reject the next shorter delays it visited.
    # Read long, one sample shorter too: where the costs at the pick's core barely tell two delays apart
    # the decision may land on the longer by round-off, and behind one sample too many no causal core fits
    # (random helmet 94, short, pure delay 19: read 23, decided 20 or 19 by the last bits of a factorisation;
    # at 20 the moved core validates at 5.7x, at 19 at 1.00x), while one sample short costs a zero.
    tries = ([extra] + ([extra - 1] if delay + extra > 0 else []) if extra < 0
             else [j for j in sorted(walked.fits, reverse=True) if 0 < j <= extra])
    best_move = None
    for extra in tries[:DELAY_TRIES] if extra else []:
        longer = compensate_delay(body, extra)
        longer_sweeps = [sweep_spectrum(compensate_delay(s, delay + extra), options.validation_band) for s in sweeps]
        moved, moved_rms = _best_trial(pick, candidates, walked, extra, longer, longer_sweeps, delay, validate, options)
        if moved is not None and moved_rms <= pick_rms * (1 + options.min_gain):
            # The decided delay first; the shorter one replaces it only when it validates clearly better.
            if best_move is None or moved_rms < best_move.rms * (1 - options.min_gain):
                best_move = MovedDelay(extra, moved, moved_rms, longer, longer_sweeps)
            if extra >= 0:
                break
    return best_move


def _best_trial(pick, candidates, walked, extra, longer, longer_sweeps, delay, validate, options):
    """(the trial of fewest states within ``min_gain`` of the lowest time-domain validation rms among those the
    sweeps' spectra accept, its rms; None, inf when none, ``fewest_states``): the pick and its neighbouring orders
    refitted behind ``extra`` samples more delay."""
    # The same poles behind the longer delay, refitted on the scan block (numerator and poles); and the
    # next lower orders' poles: the samples now in the delay line free the poles that imitated them, and
    # a freed pole, out of the band the fit sees, can drift to z = 1 (sweeps' spectra right, simulation not).
    scan_longer = block_data(longer, options.band, options.scan_seconds)
    trials: list[tuple[OrderCandidate, float]] = []
    # The pick's own refit may drop up to FREED_ORDERS poles, one at a time, below.
    # Read long, the pick's poles were spent on imitating a lead (poles run to z = -1): the next higher
    # orders of the scan may hold the structure the lead displaced (random helmet 41, short: the high-pass
    # pole missing from the pick at n 17, delay 12), and the lower ones stay (94, short: n 6 for 6, 5.7x
    # from the pick's own order and higher ones alone).
    near = range(pick.order - FREED_ORDERS, pick.order + (FREED_ORDERS + 1 if extra < 0 else 0))
    starts = [_Start(FREED_ORDERS if c is pick else 0, c.start, c.A, c.B, c.C, c.D, c.reflected, c.gamma)
              for c in [pick, *[c for c in candidates if c.order in near and c is not pick]]]
    if extra in walked.fits:
        # And from the walk's poles at that delay (refine_output_error uses only the poles): refitted there
        # from the neighbouring delay's, they may sit in another minimum than the pick's own refit reaches.
        starts.insert(1, _Start(0, pick.start + ", walked", walked.fits[extra].A, pick.B, pick.C, pick.D,
                                pick.reflected, pick.gamma))
    while starts:
        start = starts.pop(0)
        fit = refine_output_error(start.A, start.B, start.C, start.D, scan_longer, feedthrough=options.feedthrough,
                                  max_iterations=20, noise_tolerance=True)
        trial = OrderCandidate(fit.A.shape[0], start.label, sweep_rms(fit.A, fit.B, fit.C, fit.D, longer_sweeps),
                               fit.A, fit.B, fit.C, fit.D, start.reflected, start.gamma)
        # A pole at the block's radius bound (output_error.decay_bound, 1 - 2e-5 on a 1 s block at 48 kHz)
        # is a freed pole run out of the data's reach, not a coupling high-pass (a 5 Hz corner at 48 kHz is
        # |p| = 0.9993).
        settled = not at_radius_bound(np.linalg.eigvals(fit.A), scan_longer)
        accepted = trial.rms <= pick.rms * (1 + options.min_gain) and (extra < 0 or no_lead(trial, pick))
        # Simulated (0.1 s of CPU for two 9 s sweeps) only when it decides something: a trial the sweeps'
        # spectra accept, or whether a settled trial's pole is dropped below.
        trial_rms = validate(trial, delay + extra) if accepted or (start.drops and settled) else np.inf
        if accepted and np.isfinite(trial_rms):
            trials.append((trial, trial_rms))
        if start.drops and (not settled or trial_rms > trial.rms * (1 + options.min_gain)):
            # The simulation disagrees with the sweeps' spectra, or a pole ran to z = 1: drop it and refit.
            poles = without_freed_pole(np.linalg.eigvals(fit.A), options.band, longer.fs)
            if poles is not None:
                starts.append(_Start(start.drops - 1, start.label + ", freed pole dropped",
                                     lti.real_block_diagonal(poles), np.zeros((poles.size, 1)),
                                     np.zeros((1, poles.size)), np.zeros((1, 1)), start.reflected, start.gamma))
    return fewest_states(trials, options.min_gain)


def no_lead(trial, pick) -> bool:
    """Whether ``trial`` (A, B, C), refitted from ``pick`` (behind a longer delay, or on a longer block), holds its
    in-band response without imitating a lead: its Hankel norm (largest Hankel singular value, at most its peak
    gain over the whole unit circle) within MOVED_HANKEL_GROWTH of the pick's.

    The sweeps fix the response in band only. Behind a delay past the true one no causal core holds it; one with
    poles toward z = -1 whose residues cancel in band imitates the lead the delay line asks for, its gain out of
    the band thousands of times the in-band peak (random helmet 76, short, true delay 62, the plant's Hankel norm
    0.34: the pick behind 59 at 1.06x; moved to 64 at 1.08x, two real poles at -0.85 and -0.87, Hankel norm 1780
    and a balanced entry of 11.7).
    """
    try:
        grown = lti.hankel_singular_values(trial.A, trial.B, trial.C)[0]
        held = lti.hankel_singular_values(pick.A, pick.B, pick.C)[0]
    except ValueError:
        return False
    return bool(grown <= MOVED_HANKEL_GROWTH * held)


def fewest_states(trials: list[tuple[OrderCandidate, float]], min_gain: float) -> tuple[OrderCandidate | None, float]:
    """(the trial of fewest states among those within ``min_gain`` of the lowest validation rms, its rms; None,
    inf when there is none): the order search's rule, here between the moved-delay trials.

    Trials of several orders behind one delay often validate within a few parts in 10^4 of each other, all at the
    floor; the lowest rms alone is then decided by round-off (random helmet 94 FF, short session: order 4 at
    8.98738e-5 FS and order 6 at 8.98702e-5 with OpenBLAS's Sandybridge kernel, order 6 lower with its Haswell one,
    and the final models 2 and 6 states). Within ``min_gain`` of the best the fewest states win, ties on order by rms.
    """
    if not trials:
        return None, np.inf
    best = min(rms for _, rms in trials)
    return min(((trial, rms) for trial, rms in trials if rms <= best * (1 + min_gain)),
               key=lambda item: (item[0].order, item[1]))


def shorter_delays(model: Model, after, identified_behind: Callable[[int], tuple | None], enough: float):
    """(model, its comparison): the one of lowest validation rms among ``model`` (``after``: its
    ``sysid.validation.compare.Comparison`` on the sweeps) and its core identified anew behind delays 1 to
    ``SHORTER_BY`` samples shorter, longest first; ``identified_behind(delay)`` gives (model, comparison) there,
    or None when no stable core was found. The scan stops where the rms rises again, or once the best is within
    ``enough`` times the noise floor.

    The latency is read from the onset of the response, late on a slowly rising one (roll-offs:
    a response that starts as t^2), and a core behind too long a delay line must imitate a lead
    that no causal, stable core has: its spare poles run to z = -1 and the error stays above the
    floor the more, the higher the SNR (random helmet 100 FF, ear gain 20, unclipped: identified
    behind its pure delay 4 and 5, 1.01x; behind 6, 7 and 8, the onset's reading, 1.04x, 1.47x,
    2.41x). The refitted costs on the noise recording tell (the true poles: 2.79 at 4 and 5, 4.73
    at 8), the pick's poles held fixed do not: they already imitate the lead. A warm start (the
    core refined behind the shorter delay) keeps them: 2.15x -> 2.09x on the clipped session.
    Nor does ``decide_delay`` at the model's core tell, refitted below its delay for 10 iterations
    from its poles or from them with the one at the radius bound replaced: 1.027, 1.014, 1.009, 1, 1.0002
    at 4-8 on the clipped session (order 9, a pole at 0.999992), so the core is identified anew at each.
    """
    best, best_after, previous = model, after, after.rms
    for delay in range(model.delay - 1, max(model.delay - SHORTER_BY, 0) - 1, -1):
        found = identified_behind(delay)
        if found is None:
            continue
        trial, trial_after = found
        if trial_after.rms >= previous:
            # Shorter than the delay the data hold, the core loses the response's first samples and the
            # error rises again (random helmet 100 FF with a hum, delay 46 read: 1.66x, 1.11x, 1.02x, 1.06x
            # at 46, 45, 44, 43): the scan stops there.
            break
        previous = trial_after.rms
        if trial_after.rms < best_after.rms:
            best, best_after = trial, trial_after
        if best_after.ratio <= enough:
            break
    return best, best_after


def delay_totals(delay: int, samples: int) -> list[int]:
    """The total delays to try for ``samples`` more than ``delay``: the total and one sample less (not below
    ``delay``), shortest first.

    The detector's scan sees the onset of the response; a core without feedthrough starts one sample
    later, so the delay one sample shorter is tried too and the better validation kept.
    """
    return sorted({delay + samples, max(delay + samples - 1, delay)})
