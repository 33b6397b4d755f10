"""Order search with several output-error starts per order (design.md, identification step 6).

One start per order lands in local minima, and a scan that stops after two orders of
little gain stops on a plateau of them. Here every order n = 1..n_max is tried
(until the validation rms reaches the noise floor) from several starting pole sets:

- ``grid gamma=G``: the smoothed-FRF subspace model of order n at a few smoothing
  widths (the seed grid's best gamma of that order and a fixed spread of widths),
  unstable poles reflected into the unit circle instead of the candidate dropped;
- ``raw subspace``: the input/output-DFT subspace model on the raw block (no
  smoothing bias, ``subspace.data_subspace_poles``);
- ``order n-1 + real pole`` and ``order n-2 + mode``: the previous orders' refined
  poles plus a real pole, or plus a lightly damped pair at the frequency where that
  model's residual relative to the input is largest.

No start holds two coinciding poles or a pole at the block's radius bound: such poles are
replaced by distinct real poles where the fixed-pole cost wants them (``distinct_start``).

Every start is screened by the output-error cost with its poles held fixed (one linear
least-squares solve), the best few are refined (``output_error``, stopped once an iteration
gains less than the noise can tell: ``noise_tolerance``) and ranked by the validation rms on
the sweeps; the best refined model of each order is kept.

A scan that stalls far above the floor has usually missed a lightly damped mode that no
start above holds (``_insert_modes``): a pair is then added to the picked model at the
frequency and damping, from a fixed log-spaced set, whose fixed-pole cost is lowest, and
refined. It is tried as soon as ``insert_patience`` orders have gained nothing more than 1.5x
above the floor, and the scan goes on only when it does not reach the floor (random helmet 1,
thesis length: the insertion after orders 14-16 gained nothing reached the floor at n 15; the
scan had run on to order 25 before inserting the same mode at n 21; 10.7 -> 4.8 s of CPU). The
scan's end tries it once more when the scan ended above 1.5x the floor and the record moved
since the last try; below 1.5x a scan plateau is mostly the floor seen through the 1 s block:
the insertion there gained under 1 % on 7 of 8 such random helmets (4 of 15 thesis-length, 4
of 50 short), and the one it helped (short 41, 1.36x -> 1.17x in the scan) ends at the floor
without it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import lti
from ..core.thresholds import (AT_FLOOR, BLOCK_NOISE_SIGMAS, INSERT_FREQUENCIES, INSERT_PATIENCE, INSERT_Q,
                               INSERT_REFINED, INSERT_ROUNDS, MIN_GAIN, NEAR_FLOOR, NEAR_PATIENCE, NEW_MODE_Q,
                               ORDER_AT_FLOOR, ORDER_PATIENCE, REFINED_STARTS, SCAN_ITERATIONS, SCREEN_RATIO,
                               START_COINCIDE, START_GAMMAS, START_REAL_POLES, START_SEPARATION)
from ..validation.sweeps import SweepSpectrum, band_energy, rms_from_responses
from .output_error import (BlockData, added_pole_costs, linear_cost, radius_bound_mask, refine_output_error,
                           residual_spectrum)
from .subspace import SubspaceDecomposition, data_subspace_poles, reflect_unstable

__all__ = ["OrderCandidate", "search_orders", "distinct_start", "without_freed_pole"]


@dataclass
class OrderCandidate:
    """The best refined model of one order, from which start, and its validation rms (FS).

    ``gamma``: the smoothing width of the ``grid gamma=G`` start the candidate descends from (refitted,
    moved behind another delay or with a pole dropped), None for the other starts.
    """

    order: int
    start: str
    rms: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    reflected: int = 0
    gamma: int | None = None

    def to_dict(self) -> dict:
        return {"order": self.order, "start": self.start, "refined_rms": self.rms, "reflected_poles": self.reflected}


def sweep_rms(A, B, C, D, sweeps: list[SweepSpectrum]) -> float:
    """Validation rms of the core (A, B, C, D) on the (delay-compensated) sweep spectra.

    Sweeps of one length share their bins: the response is evaluated once for them.
    """
    responses = []
    for s in sweeps:
        if responses and np.array_equal(s.frequencies, sweeps[0].frequencies) and s.fs == sweeps[0].fs:
            responses.append(responses[0])
        else:
            responses.append(lti.frequency_response(A, B, C, D, np.exp(2j * np.pi * s.frequencies / s.fs)))
    return rms_from_responses(sweeps, responses)


def block_at_noise(A, block: BlockData, sweeps: list[SweepSpectrum], floor: float, feedthrough: bool) -> bool:
    """Whether the output-error residual of the poles eig(A) on ``block`` is at the block's noise level.

    Inside the sweeps' band the residual's mean square over the block (Parseval, ``band_energy``
    / L) is compared with floor^2, the output noise's mean square in that band measured from the
    two sweeps: no model can lower it further. The estimate of a sum of N complex bins of noise
    has a relative standard deviation of 1/sqrt(N) (chi-square with 2N degrees of freedom, 1.6 %
    for a 1 s block at 4 kHz); within BLOCK_NOISE_SIGMAS of it, a better model cannot be told apart on
    this block, whatever the sweeps' rms says (they weigh the bass more than the noise block does).
    """
    residual = residual_spectrum(A, block, feedthrough=feedthrough)
    frequency = np.abs(np.angle(block.z)) * block.fs / (2 * np.pi)
    inside = (frequency >= sweeps[0].frequencies[0]) & (frequency <= sweeps[0].frequencies[-1])
    if not np.any(inside):
        return False
    mean_square = band_energy(residual[inside], block.length) / block.length
    return bool(mean_square <= (1 + BLOCK_NOISE_SIGMAS / np.sqrt(np.count_nonzero(inside))) * floor**2)


def _residual_mode(poles: np.ndarray, block: BlockData, feedthrough: bool) -> np.ndarray:
    """A pair at the frequency of the largest input-relative residual of the model with these poles."""
    A = lti.real_block_diagonal(poles)
    residual = residual_spectrum(A, block, feedthrough=feedthrough)
    relative = np.abs(residual) ** 2 / np.maximum(np.abs(block.U) ** 2, 1e-300)
    # Average over about 1 % of the bins so that one noisy bin does not decide.
    width = max(1, block.z.size // 100)
    smoothed = np.convolve(relative, np.ones(width) / width, mode="same")
    return _pair(float(np.angle(block.z[int(np.argmax(smoothed))])), NEW_MODE_Q)


def distinct_start(poles: np.ndarray, block: BlockData, feedthrough: bool, added: int = 0) -> np.ndarray:
    """The starting poles with every degenerate pole replaced by a real pole placed where the
    output-error cost wants it; ``added`` real poles more placed the same way.

    A pole is degenerate when it coincides (within START_COINCIDE) with an earlier one, or sits at the
    block's radius bound (``output_error.radius_bound_mask``). Two coinciding poles give two
    identical regressor columns: the least squares is rank deficient (only their sum is fitted), and
    the two poles move apart only through the second-order terms of the iteration. A pole at the
    bound is one the block could not hold, run out to z = +-1, where it adds a smooth term in band
    and rings out of it; refined again it stays there. Both came from the scan's own chain: the real
    pole added at 0.5 beside a 0.5 the previous order kept, two poles at z = 0 from a rank-deficient
    shift-property solve, and spare poles run to the bound, inherited by every later ``order n-1 +
    real pole`` start (random helmet 41, short session: four real poles at z = -0.99998 from order
    14 on; 331 of its 820 factorisations ill-conditioned, 248 of them split for dependent columns;
    255 and 38 of 861 with these starts). Each replacement is the real pole of START_REAL_POLES, at least
    START_SEPARATION from every pole kept so far, whose fixed-pole cost (``output_error.added_pole_costs``:
    the kept poles' columns factored once) is lowest: distinct by construction, and where the kept
    poles' residual asks for a real pole. An added pole goes at 0.5, the scan's usual choice, unless
    a kept pole lies within START_SEPARATION of it; then it is placed as a replacement is. (Placing every
    added pole by its cost put 7 more of the first 43 short random helmets outside issue 10's
    criteria, 6 of them by the delay the pipeline then settled on, 3 to 4 samples off.) A start with nothing degenerate is returned as given, plus the
    added poles.

    For a model that fits in band with poles at z = -1 a too long delay is the usual cause, not the
    start: a causal core cannot imitate an advance, and poles near z = -1 with large cancelling
    residues do it in band only (helmet 41, short: the delay read 12 for the true 10; with 10 the
    search reaches 1.005x at n 18 in 3.5 s of CPU).
    """
    poles = np.asarray(poles, dtype=complex)
    # Real poles as lti.real_block_diagonal tells them; a pair is kept or replaced whole, by its upper pole.
    real = np.abs(poles.imag) < 1e-12 * np.maximum(1.0, np.abs(poles))
    at_bound = radius_bound_mask(poles, block)
    placed: list[complex] = []
    for p, is_real, bound in zip(poles, real, at_bound):
        if not is_real and p.imag < 0:
            continue
        members = [complex(p.real)] if is_real else [p, np.conj(p)]
        # A pair whose two poles coincide (a double real pole split by round-off) is degenerate too.
        coincide = (not is_real and p.imag <= START_COINCIDE / 2) or (
            bool(placed) and min(np.min(np.abs(np.array(placed) - m)) for m in members) <= START_COINCIDE)
        if not bound and not coincide:
            placed += members
    replaced = poles.size - len(placed)
    for k in range(replaced + added):
        candidates = [r for r in START_REAL_POLES
                      if not placed or np.min(np.abs(np.array(placed) - r)) >= START_SEPARATION]
        if not placed or (k >= replaced and candidates[0] == START_REAL_POLES[0]):
            placed.append(complex(candidates[0]))
            continue
        costs = added_pole_costs(lti.real_block_diagonal(np.array(placed)), [np.array([r]) for r in candidates],
                                 block, feedthrough=feedthrough)
        placed.append(complex(candidates[int(np.argmin(costs))]))
    return np.array(placed)


def without_freed_pole(poles: np.ndarray, band: tuple[float, float], fs: float) -> np.ndarray | None:
    """The poles without the one (or conjugate pair) nearest the unit circle among those whose frequency
    angle(p) fs / 2 pi (Hz) lies outside ``band``; None when every pole is in band, or when the dropped ones are
    all there is (a core of one pole or one pair: nothing left to refit).

    A fit on the band's bins leaves spare poles free outside it, and one run toward z = 1 or z = -1 rings in a
    simulation the band's bins do not show: identify's settling of a pick (``sysid.identify``) and its moved-delay
    trials (``sysid.estimation.delay.trials``) drop it and refit the rest.
    """
    frequency = np.abs(np.angle(poles)) * fs / (2 * np.pi)
    outside = np.flatnonzero((frequency < band[0]) | (frequency > band[1]))
    if outside.size == 0 or poles.size < 2:
        return None
    worst = poles[outside[np.argmax(np.abs(poles[outside]))]]
    keep = np.abs(poles - worst) > 1e-12
    if abs(worst.imag) > 0:
        keep &= np.abs(poles - np.conj(worst)) > 1e-12
    # A lone out-of-band pair (the seed's FF path behind a compressing cubic, H3 -22 dB: a 2-state start) leaves
    # no pole: output error has no core to refit, and every caller keeps what it had.
    return poles[keep] if np.any(keep) else None


def _pair(omega: float, q: float) -> np.ndarray:
    """A conjugate pair at ``omega`` (rad/sample) with quality factor ``q``: r e^{+-j omega}, r = e^{-omega / 2q}."""
    p = np.exp(-omega / (2 * q)) * np.exp(1j * omega)
    return np.array([p, np.conj(p)])


def _insert_modes(best: dict[int, OrderCandidate], block: BlockData, sweeps: list[SweepSpectrum], floor: float,
                  max_order: int, feedthrough: bool, max_iterations: int, min_gain: float) -> None:
    """Add a mode to the picked model where the output-error cost drops most, and refine (updates ``best``).

    A scan that stalls above the floor has usually missed one lightly damped mode (often
    below 60 Hz, where the smoothed-FRF starts are biased and the input-relative residual
    of ``_residual_mode`` is outweighed by noise where the input is weak); its spare poles
    imitate it badly. Instead of guessing the frequency from the residual, every pair of a
    fixed log-spaced set is screened by the fixed-pole cost (one linear solve each) added
    to the model the pipeline would pick (the lowest order within ``min_gain`` of the best
    rms; the model's own columns factored once, ``output_error.added_pole_costs``), and the best
    few are refined at order n + 2.
    """
    frequencies_hz = np.abs(np.angle(block.z)) * block.fs / (2 * np.pi)
    grid = np.geomspace(max(frequencies_hz.min(), 1.0), frequencies_hz.max(), INSERT_FREQUENCIES)
    for _ in range(INSERT_ROUNDS):
        record = min(c.rms for c in best.values())
        if record <= AT_FLOOR * floor:
            return
        base = next(best[n] for n in sorted(best) if best[n].rms <= record * (1 + min_gain))
        n = base.order + 2
        if n > max_order:
            return
        poles = np.linalg.eigvals(base.A)
        trials = [(frequency, q, _pair(2 * np.pi * frequency / block.fs, q)) for frequency in grid for q in INSERT_Q]
        # The fixed-pole cost of each trial, the base's columns factored once (``added_pole_costs``).
        costs = added_pole_costs(base.A, [pair for _, _, pair in trials], block, feedthrough=feedthrough)
        screened = [(cost, frequency, q, lti.real_block_diagonal(np.concatenate([poles, pair])))
                    for cost, (frequency, q, pair) in zip(costs, trials)]
        screened.sort(key=lambda item: item[0])
        for _, frequency, q, A in screened[:INSERT_REFINED]:
            fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), block,
                                      feedthrough=feedthrough, max_iterations=max_iterations, noise_tolerance=True)
            rms = sweep_rms(fit.A, fit.B, fit.C, fit.D, sweeps)
            if n not in best or rms < best[n].rms:
                best[n] = OrderCandidate(n, f"order {base.order} + mode at {frequency:.0f} Hz Q {q:g}", rms,
                                         fit.A, fit.B, fit.C, fit.D, base.reflected)
        if min(c.rms for c in best.values()) > 0.99 * record:
            return


def search_orders(block: BlockData, sweeps: list[SweepSpectrum], decompositions: dict[int, SubspaceDecomposition],
                  grid_gammas: dict[int, int], orders, floor: float, feedthrough: bool = False,
                  at_floor: float = ORDER_AT_FLOOR, patience: int = ORDER_PATIENCE,
                  max_iterations: int = SCAN_ITERATIONS, near_floor: float = NEAR_FLOOR,
                  near_patience: int = NEAR_PATIENCE, min_gain: float = MIN_GAIN,
                  insert_patience: int = INSERT_PATIENCE, progress=None) -> list[OrderCandidate]:
    """The best refined model of each order tried (see the module docstring).

    ``decompositions`` maps gamma to the smoothed-FRF decomposition of that width;
    ``grid_gammas`` maps an order to the seed grid's best gamma for it. Orders are tried
    in ascending order; the search ends early once a model validates within ``at_floor``
    times the noise floor ``floor`` (FS), when ``patience`` successive orders have not
    lowered the best rms by 1 % (a plateau of several orders, not the first stall), or
    when ``near_patience`` orders have not lowered it once it is within ``near_floor``
    times the floor or its residual on the block is at the block's noise level
    (``block_at_noise``). After ``insert_patience`` orders without gain more than
    ``near_floor`` times above the floor, a missed mode is inserted (``_insert_modes``); the
    scan ends there if that reaches AT_FLOOR times the floor, and its patience restarts if
    that gained 1 %.
    """
    orders = sorted(int(n) for n in orders)
    raw = data_subspace_poles(block.z, block.U, block.Y, orders, q=max(orders) + 10)
    best: dict[int, OrderCandidate] = {}
    best_so_far, since = np.inf, 0
    inserted = None  # the record after the last mode insertion
    for k, n in enumerate(orders):
        starts: list[tuple[str, np.ndarray, int, int | None]] = []
        gammas = [grid_gammas[n]] if n in grid_gammas else []
        gammas += [g for g in START_GAMMAS if g in decompositions and g not in gammas]
        for gamma in gammas:
            decomposition = decompositions[gamma]
            if n > decomposition.max_order:
                continue
            A, _ = decomposition.observability(n)
            poles, moved = reflect_unstable(np.linalg.eigvals(A))
            starts.append((f"grid gamma={gamma}", distinct_start(poles, block, feedthrough), moved, gamma))
        poles, moved = reflect_unstable(raw[n])
        starts.append(("raw subspace", distinct_start(poles, block, feedthrough), moved, None))
        if n - 1 in best:
            previous = np.linalg.eigvals(best[n - 1].A)
            starts.append((f"order {n - 1} + real pole", distinct_start(previous, block, feedthrough, added=1), 0,
                           None))
        if n - 2 in best:
            previous = np.linalg.eigvals(best[n - 2].A)
            starts.append((f"order {n - 2} + mode", distinct_start(np.concatenate(
                [previous, _residual_mode(previous, block, feedthrough)]), block, feedthrough), 0, None))
        screened = []
        for label, poles, moved, gamma in starts:
            A = lti.real_block_diagonal(poles)
            screened.append((linear_cost(A, block, feedthrough=feedthrough), label, A, moved, gamma))
        screened.sort(key=lambda item: item[0])
        # A start whose fixed-pole cost is far above the best one's rarely refines past it.
        chosen = [item for item in screened[:REFINED_STARTS] if item[0] <= SCREEN_RATIO * screened[0][0]]
        for _, label, A, moved, gamma in chosen:
            fit = refine_output_error(A, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), block,
                                      feedthrough=feedthrough, max_iterations=max_iterations, noise_tolerance=True)
            rms = sweep_rms(fit.A, fit.B, fit.C, fit.D, sweeps)
            if n not in best or rms < best[n].rms:
                best[n] = OrderCandidate(n, label, rms, fit.A, fit.B, fit.C, fit.D, moved, gamma)
        if progress:
            progress(k + 1, len(orders), "order search")
        record = min(c.rms for c in best.values())
        if record < 0.99 * best_so_far:
            best_so_far, since = record, 0
        else:
            since += 1
        # Near the floor a plateau is the floor seen through the scan block's variance, not a
        # local minimum: two orders without gain end it there. So does a plateau whose best model's
        # residual on the block is already at the block's noise level (the sweeps may still read it
        # above the floor: the bass the sweeps weigh heavily holds few bins of a short block).
        near = since >= near_patience and (record <= near_floor * floor or block_at_noise(
            min(best.values(), key=lambda c: c.rms).A, block, sweeps, floor, feedthrough))
        stop = best[n].rms <= at_floor * floor or since >= patience or near
        if not stop and since == insert_patience and record > near_floor * floor:
            # A plateau far above the floor: the missed mode first; scanning on past such a plateau
            # instead (whenever above 2x the floor) put random helmets 13 and 72 (short sessions) at
            # 1.3x at n 27, where the insertion reaches the floor.
            _insert_modes(best, block, sweeps, floor, max(orders), feedthrough, max_iterations, min_gain)
            inserted = min(c.rms for c in best.values())
            stop = inserted <= AT_FLOOR * floor
            if inserted < 0.99 * best_so_far:
                best_so_far, since = inserted, 0
        if stop:
            if progress and k + 1 < len(orders):
                progress(len(orders), len(orders), "order search")
            break
    record = min(c.rms for c in best.values())
    if record > near_floor * floor and (inserted is None or record < 0.99 * inserted):
        _insert_modes(best, block, sweeps, floor, max(orders), feedthrough, max_iterations, min_gain)
    return [best[n] for n in sorted(best)]
