"""The identification pipeline: noise recording + two sweeps -> a stable model of one path.

1. Spectra of the noise recording after its transient (``spectra``: h1 or seed-average).
2. The pure delay (latency) from the onset of the band-limited impulse response
   (``latency``); everything after this works on delay-compensated data (the ear
   signal advanced by the delay), and the delay goes into the model's ``delay``.
3. The seed's grid over smoothing width gamma and order n of the frequency-domain
   subspace method, ranked by the true validation rms on both sweeps (``grid``).
4. Beyond the seed (design.md, identification steps 5 and 6): an order search with
   several output-error starts per order on the raw DFT of the noise recording
   (``order_search``), up to ``max_order`` or until the validation rms reaches the
   noise floor; the lowest order within ``min_gain`` of the best is refined on a
   longer block. Both the seed's choice and the refined model are reported; the
   refined one is returned when it validates better. A pick whose simulated sweeps
   disagree with the sweeps' spectra loses its out-of-band poles run to the unit
   circle (``_settle``).
5. The onset's delay errs short by the smoothing kernel's lead (and long on a slowly
   rising response); the picked model's poles say by how much (``latency.refine_delay``),
   read short, its core refitted one sample at a time settles it (``latency.walk_delay``:
   the largest delay whose refit costs within the noise of the best), and the samples its
   core spent imitating delay move into the delay line (or back out of it) before the
   final refinement.
6. States the data did not ask for leave (``reduction``): poles the final refinement parked at
   the block's radius bound, states no balanced realisation of the full order holds, and the
   balanced tail whose Hankel singular values sum to at most 1e-3 of the largest, each kept
   out only when the validation rms stays within its tolerance (the provenance's
   ``refinement.reduced`` says what left).

Every model leaves balanced (``lti.balanced_realisation``): entries of order one,
whatever the coordinates the subspace or output-error fit produced.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from .core import lti
from .core.errors import IdentificationError
from .core.model import PATHS, Model
from .core.thresholds import IDENTIFICATION_BAND, TRANSIENT_S
from .estimation.delay import LatencyEstimate, compensate_delay, decide_delay, estimate_latency
from .estimation.grid import DEFAULT_GAMMAS, DEFAULT_ORDERS, GridResult, grid_search
from .estimation.order_search import START_GAMMAS, OrderCandidate, search_orders, sweep_rms
from .estimation.output_error import at_radius_bound, block_data, refine_output_error
from .estimation.reduction import without_degenerate_states
from .estimation.spectra import ESTIMATORS, Spectra, estimate_spectra, smoothed_response
from .estimation.subspace import SubspaceDecomposition
from .estimation.uncertainty import frequency_response_band
from .io.lines import undriven_lines, without_lines
from .io.recordings import Recording, RecordingFile, check_same_rate
from .validation.sweeps import (VALIDATION_BAND, check_repeats, noise_floor, repeat_lag, simulated_rms, sweep_spectrum,
                                without_repeat_lines)

__all__ = ["IdentificationOptions", "Identification", "identify"]

# Lower orders refitted behind a delay moved by latency.refine_delay (their poles need not imitate it).
_FREED_ORDERS = 2
# Out-of-band poles dropped at most from a pick whose simulation disagrees with the sweeps' spectra (_settle).
_SETTLE_DROPS = 4
# Delays walked to (latency.walk_delay) tried at most on the sweeps, longest first.
_DELAY_TRIES = 3


@dataclass(frozen=True)
class IdentificationOptions:
    """Options of ``identify``; the defaults are the seed's grid and the corrected estimator."""

    estimator: str = "h1"
    gammas: tuple[int, ...] = DEFAULT_GAMMAS
    orders: tuple[int, ...] = DEFAULT_ORDERS
    band: tuple[float, float] = IDENTIFICATION_BAND
    validation_band: tuple[float, float] = VALIDATION_BAND
    transient_s: float = TRANSIENT_S
    feedthrough: bool = False
    refine: bool = True
    scan_seconds: float = 1.0
    refine_seconds: float = 10.0
    # Estimate the pure delay first and fit the core on delay-compensated data.
    latency: bool = True
    max_delay: int = 400
    # The order search tries every order up to max_order unless the validation rms reaches
    # at_floor times the noise floor first; it picks the lowest order within min_gain of the best.
    max_order: int = 30
    at_floor: float = 1.02
    min_gain: float = 0.03


@dataclass
class Identification:
    """What ``identify`` found: the model, the grid, both choices and their figures."""

    model: Model
    grid: GridResult
    spectra: Spectra
    noise_floor: float
    seed_model: Model
    seed_rms: float
    refined_rms: float | None
    order_scan: list[dict] = field(default_factory=list)
    stage_seconds: dict[str, float] = field(default_factory=dict)
    latency: LatencyEstimate | None = None


def _check_inputs(noise: Recording, sweeps: list[Recording], options: IdentificationOptions) -> int:
    """Checks the inputs; returns the lag (samples) aligning the second sweep to the first."""
    if options.estimator not in ESTIMATORS:
        raise IdentificationError(f"estimator must be one of {', '.join(ESTIMATORS)}; found {options.estimator!r}")
    if len(sweeps) != 2:
        raise IdentificationError(f"need exactly two validation sweeps; found {len(sweeps)}")
    check_same_rate([noise, *sweeps])
    lag = repeat_lag(*sweeps)
    check_repeats(*sweeps, lag=lag)
    return lag


def identify(noise: Recording | RecordingFile, sweeps: list[Recording], path: str = "fb",
             options: IdentificationOptions | None = None, progress=None) -> Identification:
    """Identify a stable model of ``path`` from a noise recording and two sweeps.

    A noise recording opened with ``sysid.io.recordings.open_recording`` is read in blocks:
    memory stays bounded whatever its length (the sweeps are held in memory).
    """
    # The matrices are at most a few thousand by sixty: BLAS threads only add overhead,
    # and on a loaded machine they spin (a QR took 0.3 s of CPU with two threads, 5 ms with one).
    with threadpool_limits(limits=1, user_api="blas"):
        return _identify(noise, sweeps, path, options, progress)


def _identify(noise, sweeps, path, options, progress) -> Identification:
    options = options or IdentificationOptions()
    if path not in PATHS:
        raise IdentificationError(f"path must be one of {', '.join(PATHS)}; found {path!r}")
    lag = _check_inputs(noise, sweeps, options)
    # A hum or engine order in the sweeps is neither plant nor output noise: fitted beside each sweep's
    # response and taken out, it inflates neither the floor nor the rms the order search steers by.
    head = noise.trimmed(options.transient_s).head(max(options.refine_seconds, options.scan_seconds))
    sweeps, lines = without_repeat_lines(*sweeps, options.validation_band, lag=lag,
                                         known=undriven_lines(head, options.band))
    fs = noise.fs
    seconds: dict[str, float] = {}

    t0 = time.perf_counter()
    body = noise.trimmed(options.transient_s)
    floor = noise_floor(sweeps[0], sweeps[1], options.validation_band, lag=lag)
    latency = None
    delay = 0
    if options.latency:
        latency = estimate_latency(estimate_spectra(body, "h1"), options.max_delay)
        delay = latency.samples
        body = body.advanced(delay) if isinstance(body, RecordingFile) else compensate_delay(body, delay)
    core_sweeps = [compensate_delay(s, delay) for s in sweeps]
    spectra = estimate_spectra(body, options.estimator)
    # What follows (output-error blocks, the band's covariance and misfit) uses the first refine_seconds only,
    # read from a file or in memory alike: a noise recording read from its file in blocks gave its spectra above,
    # and only those seconds are held in memory.
    body = body.head(max(options.refine_seconds, options.scan_seconds))
    # The sweeps' lines in the noise recording too: the output-error fit on its raw DFT bends the core toward
    # a line's bin (random helmet 101 FB, 50 Hz hum: a core 180-360x off at 32-63 Hz).
    body = without_lines(body, lines)
    sweep_spectra = [sweep_spectrum(s, options.validation_band) for s in core_sweeps]
    seconds["spectra"] = time.perf_counter() - t0

    grid = grid_search(spectra, sweep_spectra, options.band, options.gammas, options.orders,
                       feedthrough=options.feedthrough, progress=progress)
    seconds.update(grid.stage_seconds)

    chosen = grid.chosen
    provenance = {
        "estimator": options.estimator,
        "band_hz": list(options.band),
        "validation_band_hz": list(options.validation_band),
        "transient_s": options.transient_s,
        "noise_file": noise.path,
        "sweep_files": [s.path for s in sweeps],
        "latency": latency.to_dict() if latency else None,
        "grid": {"gammas": [int(grid.gammas[0]), int(grid.gammas[-1])], "orders": [int(grid.orders[0]), int(grid.orders[-1])],
                 "candidates": int(grid.rms.size), "stable": int(np.isfinite(grid.rms).sum())},
        "seed_choice": {"gamma": chosen.gamma, "order": chosen.order},
        "noise_floor": floor,
    }
    if lines:
        provenance["sweep_lines_hz"] = [round(float(f), 3) for f in lines]
    # Balanced before it becomes a Model (the subspace fit's coordinates are arbitrary).
    A, B, C, D = lti.balanced_realisation(chosen.fit.A, chosen.fit.B, chosen.fit.C, chosen.fit.D)
    seed_model = Model(path=path, fs=fs, A=A, B=B, C=C, D=D, delay=delay,
                       identification=dict(provenance, method="seed grid (smoothed FRF + subspace)"))
    seed_rms = simulated_rms(seed_model, sweeps, options.validation_band)
    provenance["seed_choice"]["rms"] = seed_rms

    result_model, refined_rms, scan = seed_model, None, []
    if options.refine:
        t0 = time.perf_counter()
        # The band-limited kernel's lead (samples): how far short the onset may have read (latency module docstring).
        lead = int(np.ceil(fs / (2 * latency.top_hz))) if latency else 0
        result_model, refined_rms, scan, extra = _refine(body, sweeps, sweep_spectra, spectra, grid, path, delay, floor,
                                                         options, provenance, progress, lead)
        seconds["refinement"] = time.perf_counter() - t0
        if extra is not None and refined_rms < seed_rms:
            # The model moved ``extra`` samples of its core into the delay line (latency.refine_delay).
            body = compensate_delay(body, extra)
            delay += extra
            latency = dataclasses.replace(latency, samples=delay, refined_by=extra)
            result_model.identification["latency"] = latency.to_dict()
        if refined_rms >= seed_rms:
            # Keep the seed's choice, but say what the refinement tried and why it was dropped.
            seed_model.identification["refinement"] = dict(result_model.identification["refinement"], rms=refined_rms,
                                                           rejected="validated worse than the seed grid's choice")
            result_model = seed_model
    final_rms = seed_rms if result_model is seed_model else refined_rms
    start_gamma = result_model.identification.get("refinement", {}).get("start_gamma", chosen.gamma)
    result_model.identification.update({
        "gamma": start_gamma,
        "order": result_model.order,
        "delay": result_model.delay,
        "rms": final_rms,
        "noise_floor": floor,
        "refined": result_model is not seed_model,
    })
    # The 95 % band of the returned model (sysid.estimation.uncertainty), from the delay-compensated noise block it was refined on.
    t0 = time.perf_counter()
    core = Model(path=path, fs=fs, A=result_model.A, B=result_model.B, C=result_model.C, D=result_model.D)
    result_model.uncertainty = frequency_response_band(core, body, spectra, options.band, options.refine_seconds).to_dict()
    seconds["uncertainty"] = time.perf_counter() - t0
    return Identification(result_model, grid, spectra, floor, seed_model, seed_rms, refined_rms, scan, seconds, latency)


def _decompositions(spectra: Spectra, grid: GridResult, band, feedthrough: bool, max_order: int):
    """Smoothed-FRF subspace decompositions at the starting widths, and each order's best grid gamma."""
    grid_gammas = {}
    for j, order in enumerate(grid.orders):
        column = grid.rms[:, j]
        if np.any(np.isfinite(column)):
            grid_gammas[int(order)] = int(grid.gammas[int(np.nanargmin(column))])
    limit = spectra.nperseg // 2
    widths = sorted({g for g in (*grid_gammas.values(), *START_GAMMAS) if g <= limit})
    decompositions = {}
    for gamma in widths:
        frf = smoothed_response(spectra, gamma, band)
        q = min(max_order + 2, 2 * frf.frequencies.size)
        decompositions[gamma] = SubspaceDecomposition(2 * np.pi * frf.frequencies / spectra.fs, frf.g, q=q,
                                                      feedthrough=feedthrough)
    return decompositions, grid_gammas


def _without_freed_pole(poles: np.ndarray, band: tuple[float, float], fs: float) -> np.ndarray | None:
    """The poles without the one (or conjugate pair) nearest the unit circle among those whose frequency
    angle(p) fs / 2 pi (Hz) lies outside ``band``; None when every pole is in band."""
    frequency = np.abs(np.angle(poles)) * fs / (2 * np.pi)
    outside = np.flatnonzero((frequency < band[0]) | (frequency > band[1]))
    if outside.size == 0 or poles.size < 2:
        return None
    worst = poles[outside[np.argmax(np.abs(poles[outside]))]]
    keep = np.abs(poles - worst) > 1e-12
    if abs(worst.imag) > 0:
        keep &= np.abs(poles - np.conj(worst)) > 1e-12
    return poles[keep]


def _settle(pick: OrderCandidate, pick_rms: float, block, sweep_spectra, time_rms, delay: int, options):
    """The pick with out-of-band poles run to the unit circle dropped, when that validates better in time.

    A fit on the band's bins leaves spare poles free outside it; one that runs toward z = 1 or
    z = -1 (|p| at the block's radius bound, ``output_error.decay_bound``) is invisible in the sweeps' spectra
    but rings in the simulated sweeps (random helmet 63, short session: sweeps' spectra 1.1x,
    simulation 118x; 41: 6.8e6x). While the time-domain validation rms ``pick_rms`` exceeds
    the spectra's (``pick.rms``) by more than ``min_gain``, the out-of-band pole nearest the
    unit circle is dropped and the rest refitted on ``block``, up to _SETTLE_DROPS times; the
    refit with the lowest time-domain rms is kept if it beats the pick's.
    """
    current, best, best_rms = pick, pick, pick_rms
    current_rms = pick_rms
    for _ in range(_SETTLE_DROPS):
        if current_rms <= current.rms * (1 + options.min_gain):
            break
        poles = _without_freed_pole(np.linalg.eigvals(current.A), options.band, block.fs)
        if poles is None:
            break
        n = poles.size
        fit = refine_output_error(lti.real_block_diagonal(poles), np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)),
                                  block, feedthrough=options.feedthrough, max_iterations=20, noise_tolerance=True)
        current = OrderCandidate(n, pick.start + ", free pole dropped", sweep_rms(fit.A, fit.B, fit.C, fit.D, sweep_spectra),
                                 fit.A, fit.B, fit.C, fit.D, pick.reflected)
        current_rms = time_rms(current, delay)
        if current_rms < best_rms:
            best, best_rms = current, current_rms
    return best, best_rms


def _refine(body, sweeps, sweep_spectra, spectra, grid, path, delay, floor, options, provenance, progress, lead=0):
    scan_block = block_data(body, options.band, options.scan_seconds)
    # Orders given explicitly are searched as given; the seed's default 1..20 widens to max_order.
    orders = range(1, options.max_order + 1) if tuple(options.orders) == DEFAULT_ORDERS else options.orders
    decompositions, grid_gammas = _decompositions(spectra, grid, options.band, options.feedthrough, max(orders))
    candidates = search_orders(scan_block, sweep_spectra, decompositions, grid_gammas, orders, floor,
                               feedthrough=options.feedthrough, at_floor=options.at_floor, min_gain=options.min_gain,
                               progress=progress)
    scan = [c.to_dict() for c in candidates]
    # The lowest order within min_gain of the best validation rms.
    best_rms = min(c.rms for c in candidates)
    pick = next(c for c in candidates if c.rms <= best_rms * (1 + options.min_gain))
    def time_rms(c, d):
        # The validation rms by time-domain simulation: a pole the in-band fit leaves near z = 1
        # (a spare one, out of the band it sees) shows only here, not in the sweeps' spectra.
        core = Model(path=path, fs=body.fs, A=c.A, B=c.B, C=c.C, D=c.D, delay=d)
        return simulated_rms(core, sweeps, options.validation_band)

    pick_rms = time_rms(pick, delay)
    pick, pick_rms = _settle(pick, pick_rms, scan_block, sweep_spectra, time_rms, delay, options)
    extra = None
    if options.latency:
        # The onset errs short by the smoothing kernel's lead, or long on a slowly rising response; the
        # picked core's poles say by how much.
        # Read short (or right), the refitted costs settle it, walked one sample at a time from the fixed poles'
        # answer; read long, the refitted costs below the onset's delay (latency.decide_delay, shared with refits).
        walked = decide_delay(pick.A, body, options.band, options.scan_seconds, delay, feedthrough=options.feedthrough,
                              lead=lead, long_seconds=options.refine_seconds)
        extra = walked.extra
        # The walk's answer first; a trial the sweeps reject (a freed pole run toward z = 1 rings in the simulated
        # sweeps: random helmet 2, short, one sample past the true delay at 84x) the next shorter delays it visited.
        # Read long, one sample shorter too: where the costs at the pick's core barely tell two delays apart
        # the decision may land on the longer by round-off, and behind one sample too many no causal core fits
        # (random helmet 94, short, pure delay 19: read 23, decided 20 or 19 by the last bits of a factorisation;
        # at 20 the moved core validates at 5.7x, at 19 at 1.00x), while one sample short costs a zero.
        tries = ([extra] + ([extra - 1] if delay + extra > 0 else []) if extra < 0
                 else [j for j in sorted(walked.fits, reverse=True) if 0 < j <= extra])
        moved_by, best_move = 0, None
        for extra in tries[:_DELAY_TRIES] if extra else []:
            longer = compensate_delay(body, extra)
            longer_sweeps = [sweep_spectrum(compensate_delay(s, delay + extra), options.validation_band) for s in sweeps]
            # The same poles behind the longer delay, refitted on the scan block (numerator and poles); and the
            # next lower orders' poles: the samples now in the delay line free the poles that imitated them, and
            # a freed pole, out of the band the fit sees, can drift to z = 1 (sweeps' spectra right, simulation not).
            scan_longer = block_data(longer, options.band, options.scan_seconds)
            moved, moved_rms = None, np.inf
            # (poles still to drop, label, start model, reflected poles): the pick's own refit may drop up to
            # _FREED_ORDERS poles, one at a time, below.
            # Read long, the pick's poles were spent on imitating a lead (poles run to z = -1): the next higher
            # orders of the scan may hold the structure the lead displaced (random helmet 41, short: the high-pass
            # pole missing from the pick at n 17, delay 12), and the lower ones stay (94, short: n 6 for 6, 5.7x
            # from the pick's own order and higher ones alone).
            near = range(pick.order - _FREED_ORDERS, pick.order + (_FREED_ORDERS + 1 if extra < 0 else 0))
            starts = [(_FREED_ORDERS if c is pick else 0, c.start, c.A, c.B, c.C, c.D, c.reflected)
                      for c in [pick, *[c for c in candidates if c.order in near and c is not pick]]]
            if extra in walked.fits:
                # And from the walk's poles at that delay (refine_output_error uses only the poles): refitted there
                # from the neighbouring delay's, they may sit in another minimum than the pick's own refit reaches.
                starts.insert(1, (0, pick.start + ", walked", walked.fits[extra].A, pick.B, pick.C, pick.D,
                                  pick.reflected))
            while starts:
                drops, label, A0, B0, C0, D0, reflected = starts.pop(0)
                fit = refine_output_error(A0, B0, C0, D0, scan_longer, feedthrough=options.feedthrough, max_iterations=20,
                                          noise_tolerance=True)
                trial = OrderCandidate(fit.A.shape[0], label, sweep_rms(fit.A, fit.B, fit.C, fit.D, longer_sweeps),
                                       fit.A, fit.B, fit.C, fit.D, reflected)
                # A pole at the block's radius bound (output_error.decay_bound, 1 - 2e-5 on a 1 s block at 48 kHz)
                # is a freed pole run out of the data's reach, not a coupling high-pass (a 5 Hz corner at 48 kHz is
                # |p| = 0.9993).
                settled = not at_radius_bound(np.linalg.eigvals(fit.A), scan_longer)
                accepted = trial.rms <= pick.rms * (1 + options.min_gain)
                # Simulated (0.1 s of CPU for two 9 s sweeps) only when it decides something: a trial the sweeps'
                # spectra accept, or whether a settled trial's pole is dropped below.
                trial_rms = time_rms(trial, delay + extra) if accepted or (drops and settled) else np.inf
                if accepted and trial_rms < moved_rms:
                    moved, moved_rms = trial, trial_rms
                if drops and (not settled or trial_rms > trial.rms * (1 + options.min_gain)):
                    # The simulation disagrees with the sweeps' spectra, or a pole ran to z = 1: drop it and refit.
                    poles = _without_freed_pole(np.linalg.eigvals(fit.A), options.band, body.fs)
                    if poles is not None:
                        starts.append((drops - 1, label + ", freed pole dropped", lti.real_block_diagonal(poles),
                                       np.zeros((poles.size, 1)), np.zeros((1, poles.size)), np.zeros((1, 1)), reflected))
            if moved is not None and moved_rms <= pick_rms * (1 + options.min_gain):
                # The decided delay first; the shorter one replaces it only when it validates clearly better.
                if best_move is None or moved_rms < best_move[0] * (1 - options.min_gain):
                    best_move = (moved_rms, moved, extra, longer, longer_sweeps)
                if extra >= 0:
                    break
        if best_move is not None:
            pick_rms, pick, moved_by, body, sweep_spectra = best_move
            delay += moved_by
        extra = moved_by  # 0 when the sweeps disagree with every try: the onset's delay stays
    block = block_data(body, options.band, options.refine_seconds)
    # Stopped once an iteration gains less than the noise can tell (output_error's noise_tolerance, as every
    # refinement here): the pick sits near the long block's minimum, and MINPACK's default tolerance crawled
    # on for 50 iterations (random helmet 5, thesis length: 18 s of CPU for 4e-6 of the cost). A pair the scan ran to
    # the real axis is refined as two real poles (output_error.split_near_real_pairs; random helmet 17: 44 -> 16
    # evaluations of the 10 s block, 1016 noise variances off the cost against 420; 11.5 -> 8.1 s of CPU).
    oe = refine_output_error(pick.A, pick.B, pick.C, pick.D, block, feedthrough=options.feedthrough, max_iterations=60,
                             noise_tolerance=True, split_near_real=True)
    A, B, C, D = oe.A, oe.B, oe.C, oe.D
    rms = time_rms(oe, delay)
    if rms > pick_rms:
        # The longer block did not help on the sweeps: keep the scan's model of that order.
        A, B, C, D, rms = pick.A, pick.B, pick.C, pick.D, pick_rms
    # States the data did not ask for out: poles parked at the block's radius bound, states no balanced
    # realisation of the full order holds (sysid.estimation.reduction).
    reduced = without_degenerate_states(A, B, C, D, rms, block, lambda c: time_rms(c, delay), options.min_gain,
                                        options.feedthrough)
    A, B, C, D, rms = reduced.A, reduced.B, reduced.C, reduced.D, reduced.rms
    gamma = int(pick.start.split("=")[1]) if pick.start.startswith("grid gamma=") else grid_gammas.get(pick.order, grid.chosen.gamma)
    model = Model(path=path, fs=body.fs, A=A, B=B, C=C, D=D, delay=delay,
                  identification=dict(provenance, method="latency, seed grid, then order search with output-error "
                                                         "refinement from several starts on raw DFT data",
                                      refinement={"start_gamma": gamma, "start": pick.start, "order": pick.order,
                                                  "reflected_poles": pick.reflected, "reduced": reduced.removed,
                                                  "block_seconds": block.length / body.fs, "order_scan": scan}))
    return model, rms, scan, extra
