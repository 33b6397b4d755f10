"""The identification pipeline: noise recording + two sweeps -> a stable model of one path.

1. Spectra of the noise recording after its transient (``spectra``: h1 or seed-average).
2. The pure delay (latency) from the onset of the band-limited impulse response
   (``sysid.estimation.delay.estimate_latency``); everything after this works on delay-compensated
   data (the ear signal advanced by the delay), and the delay goes into the model's ``delay``.
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
   rising response); the picked model's core decides by how much (``sysid.estimation.delay``:
   fixed-pole costs, then its core refitted one sample at a time), and the samples its
   core spent imitating delay move into the delay line (or back out of it) before the
   final refinement when a core behind the new delay validates as well
   (``sysid.estimation.delay.moved_delay``); where the pick rang, the scan is run again behind it.
6. States the data did not ask for leave (``reduction``): a spare pole out of the band, poles the
   final refinement parked at the block's radius bound, states no balanced realisation of the full order holds, and the
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
from .core.board import board_cost
from .core.errors import IdentificationError
from .core.model import PATHS, Model
from .core.thresholds import (DEFAULT_GAMMAS, DEFAULT_ORDERS, IDENTIFICATION_BAND, MIN_GAIN, NEAR_FLOOR,
                              ORDER_AT_FLOOR, SETTLE_DROPS, START_GAMMAS, TRANSIENT_S, UNCERTAINTY_MAX_ORDER)
from .estimation import route
from .estimation.delay import LatencyEstimate, TrialOptions, compensate_delay, estimate_latency, moved_delay, no_lead
from .estimation.grid import GridResult, grid_search
from .estimation.long_model import long_model
from .estimation.long_route import LongEstimate, fir_band, long_estimate
from .estimation.order_curve import OrderCurve
from .estimation.order_search import OrderCandidate, search_orders, sweep_rms, without_freed_pole
from .estimation.output_error import at_radius_bound, block_data, refine_output_error
from .estimation.reduction import Reduced, without_degenerate_states, without_spare_pole
from .estimation.spectra import ESTIMATORS, Spectra, estimate_spectra, response, smoothed_response
from .estimation.subspace import SubspaceDecomposition
from .estimation.uncertainty import frequency_response_band
from .io.lines import undriven_lines, without_lines
from .io.recordings import Recording, RecordingFile, check_noise_length, check_same_rate
from .validation.sweeps import (VALIDATION_BAND, SweepSpectrum, check_repeats, noise_floor, repeat_lag, simulated_rms,
                                sweep_spectrum, without_repeat_lines)

__all__ = ["IdentificationOptions", "Identification", "identify"]


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
    # The user's cap on the model's states (what the board can afford), None: the lowest order at the noise floor
    # the data allow. The order search tries every order up to SEARCH_MAX_ORDER (and the cap) unless the validation rms
    # reaches at_floor times the noise floor first; every route picks the lowest order within min_gain of the best.
    max_order: int | None = None
    at_floor: float = ORDER_AT_FLOOR
    min_gain: float = MIN_GAIN
    # "auto" (sysid.estimation.route decides), "search" (the order search only) or "long" (the long route only).
    route: str = "auto"


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
    route.check_route(options)
    if len(sweeps) != 2:
        raise IdentificationError(f"need exactly two validation sweeps; found {len(sweeps)}")
    check_same_rate([noise, *sweeps])
    check_noise_length(noise, options.transient_s)
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

    grid = grid_search(spectra, sweep_spectra, options.band, options.gammas, route.grid_orders(options),
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
        "max_order": options.max_order,
    }
    if lines:
        provenance["sweep_lines_hz"] = [round(float(f), 3) for f in lines]
    # Balanced before it becomes a Model (the subspace fit's coordinates are arbitrary).
    A, B, C, D = lti.balanced_realisation(chosen.fit.A, chosen.fit.B, chosen.fit.C, chosen.fit.D)
    seed_model = Model(path=path, fs=fs, A=A, B=B, C=C, D=D, delay=delay,
                       identification=dict(provenance, method="seed grid (smoothed FRF + subspace)"))
    seed_rms = simulated_rms(seed_model, sweeps, options.validation_band)
    provenance["seed_choice"]["rms"] = seed_rms

    picked = _Candidate("seed grid", seed_model, seed_rms, body, latency)
    refined_rms, scan, long = None, [], None
    if options.refine:
        candidates = []
        if route.wants_long(options):
            t0 = time.perf_counter()
            long = long_estimate(noise, sweeps, floor, options.band, options.validation_band, options.transient_s,
                                 options.max_delay if options.latency else 0, options.feedthrough, options.at_floor,
                                 options.min_gain, route.ladder_orders(options), options.route == "long")
            seconds.update(long.seconds)
            if long.held or options.route == "long":
                t0 = time.perf_counter()
                made = long_model(long, noise, sweeps, lines, floor, provenance, path, options)
                moved = None if latency is None else dataclasses.replace(latency, samples=long.line, refined_by=None)
                candidates.append(_Candidate("long route", made.model, made.rms, made.body, moved))
                seconds["long route"] = time.perf_counter() - t0
        first = candidates[0] if candidates else None
        if route.wants_search(options, long, first and first.rms, first and first.model.order, floor):
            t0 = time.perf_counter()
            candidates.append(_search_candidate(_Behind(body, sweeps, sweep_spectra, delay, path, options), spectra,
                                                grid, floor, provenance, progress, latency))
            seconds["refinement"] = time.perf_counter() - t0
        picked = _better(candidates, options.min_gain)
        refined_rms, scan = picked.rms, picked.scan
        if picked.rms >= seed_rms:
            # Keep the seed's choice, but say what the refinement tried and why it was dropped.
            seed_model.identification["refinement"] = dict(picked.model.identification.get("refinement", {}),
                                                           rms=picked.rms,
                                                           rejected="validated worse than the seed grid's choice")
            picked = _Candidate("seed grid", seed_model, seed_rms, body, latency)
        _record_routes(picked, candidates, long, floor, options)
    result_model = picked.model
    # A model kept from the seed grid records its own gamma, not the one the rejected refinement started from.
    start_gamma = (chosen.gamma if result_model is seed_model
                   else result_model.identification.get("refinement", {}).get("start_gamma", chosen.gamma))
    result_model.identification.update({
        "gamma": start_gamma,
        "order": result_model.order,
        "delay": result_model.delay,
        "rms": picked.rms,
        "noise_floor": floor,
        "refined": result_model is not seed_model,
    })
    # The 95 % band of the returned model (sysid.estimation.uncertainty), from the delay-compensated noise block it was
    # refined on; above UNCERTAINTY_MAX_ORDER states, from the FIR the long route reduced (its covariance's cost).
    t0 = time.perf_counter()
    core = Model(path=path, fs=fs, A=result_model.A, B=result_model.B, C=result_model.C, D=result_model.D)
    if picked.route == "long route" and result_model.order > UNCERTAINTY_MAX_ORDER:
        f = response(spectra, options.band).frequencies
        result_model.uncertainty = fir_band(long, (core.A, core.B, core.C, core.D), f)
    else:
        result_model.uncertainty = frequency_response_band(core, picked.body, spectra, options.band,
                                                           options.refine_seconds).to_dict()
    seconds["uncertainty"] = time.perf_counter() - t0
    return Identification(result_model, grid, spectra, floor, seed_model, seed_rms, refined_rms, scan, seconds,
                          picked.latency)


@dataclass
class _Candidate:
    """A model one route returned, its time-domain validation rms (FS), the noise block behind its delay (for its
    95 % band), its delay's estimate and the order scan that found it (the order search's)."""

    route: str
    model: Model
    rms: float
    body: Recording
    latency: LatencyEstimate | None
    scan: list[dict] = field(default_factory=list)


def _better(candidates: list[_Candidate], min_gain: float) -> _Candidate:
    """The fewest states among the candidates within ``min_gain`` of the best validation rms (the order search's
    rule between routes)."""
    best = min(c.rms for c in candidates)
    return min((c for c in candidates if c.rms <= best * (1 + min_gain)), key=lambda c: (c.model.order, c.rms))


def _search_candidate(data: _Behind, spectra: Spectra, grid: GridResult, floor: float, provenance: dict, progress,
                      latency: LatencyEstimate | None) -> _Candidate:
    """The order search's route (steps 4-6 of the module docstring) as a candidate."""
    # The band-limited kernel's lead (samples): how far short the onset may have read.
    lead = latency.lead if latency else 0
    model, rms, scan, extra = _refine(data, spectra, grid, floor, dict(provenance, route="order search"), progress, lead)
    body = data.body
    if extra:
        # The model moved ``extra`` samples of its core into the delay line (sysid.estimation.delay.moved_delay).
        body = compensate_delay(body, extra)
        latency = dataclasses.replace(latency, samples=data.delay + extra, refined_by=extra)
    elif extra is not None and latency is not None:
        latency = dataclasses.replace(latency, refined_by=0)
    if latency is not None and extra is not None:
        model.identification["latency"] = latency.to_dict()
    return _Candidate("order search", model, rms, body, latency, scan)


def _record_routes(picked: _Candidate, candidates: list[_Candidate], long: LongEstimate | None, floor: float,
                   options: IdentificationOptions) -> None:
    """The routes tried and the order/error/cost curve into the picked model's provenance (``sysid.core.model``)."""
    info = picked.model.identification
    info["route"] = picked.route
    info["routes"] = [{"route": c.route, "order": c.model.order, "rms": c.rms, "ratio": round(c.rms / floor, 4)}
                      for c in candidates]
    scanned = {int(c["order"]): float(c["refined_rms"]) for c in picked.scan or next(
        (c.scan for c in candidates if c.scan), [])}
    if long is not None and long.curve is not None:
        curve = long.curve
        for n, r in scanned.items():
            curve.refined[n] = min(r, curve.refined.get(n, np.inf))
        info["long_estimate"] = long.to_dict()
    elif scanned:
        A, B, C = picked.model.A, picked.model.B, picked.model.C
        hsv = lti.hankel_singular_values(A, B, C) if picked.model.stable else np.zeros(0)
        curve = OrderCurve(sorted(scanned), [scanned[n] for n in sorted(scanned)], floor, hsv,
                           "order search (output error from several starts per order)")
    else:
        return
    curve.chosen = picked.model.order
    info["order_curve"] = curve.to_dict()
    cap = options.max_order
    if cap is not None and long is not None and long.curve is not None:
        needed = long.curve.lowest_at_floor(options.at_floor, options.min_gain)
        if needed > picked.model.order and picked.rms > options.at_floor * floor * (1 + options.min_gain):
            info["capped"] = {"max_order": cap, "ratio": round(picked.rms / floor, 4), "floor_order": needed,
                              "floor_ratio": round(long.curve.ratio(needed), 4),
                              "floor_instructions": board_cost(needed).step}


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


@dataclass(frozen=True)
class _Behind:
    """What the refinement's steps share: the data behind the current delay, and the options.

    ``body``: the noise recording's first seconds, its lines out, the ear signal advanced by ``delay``;
    ``sweeps``: the two sweeps, their lines out; ``sweep_spectra``: their DFT bins behind ``delay``.
    """

    body: Recording
    sweeps: list[Recording]
    sweep_spectra: list[SweepSpectrum]
    delay: int
    path: str
    options: IdentificationOptions

    def time_rms(self, c, delay: int) -> float:
        """The validation rms of the core c (A, B, C, D) behind ``delay`` by time-domain simulation: a pole
        the in-band fit leaves near z = 1 (a spare one, out of the band it sees) shows only here, not in the
        sweeps' spectra."""
        core = Model(path=self.path, fs=self.body.fs, A=c.A, B=c.B, C=c.C, D=c.D, delay=delay)
        return simulated_rms(core, self.sweeps, self.options.validation_band)


def _refine(data: _Behind, spectra: Spectra, grid: GridResult, floor: float, provenance: dict, progress, lead: int = 0):
    """(the refined model, its validation rms, the order scan, samples moved into the delay line or None when the
    delay was not refined): order search and pick, settling, moved delay, final refinement, reduction."""
    options = data.options
    scan_block = block_data(data.body, options.band, options.scan_seconds)
    candidates, grid_gammas = _order_search(data, scan_block, spectra, grid, floor, progress)
    scan = [c.to_dict() for c in candidates]
    # The lowest order within min_gain of the best validation rms.
    best_rms = min(c.rms for c in candidates)
    pick = next(c for c in candidates if c.rms <= best_rms * (1 + options.min_gain))
    first_rms = data.time_rms(pick, data.delay)
    # Rang: the simulated sweeps far from their spectra (a pole run toward the unit circle out of the band).
    rang = first_rms > pick.rms * (1 + options.min_gain)
    pick, pick_rms = _settle(pick, first_rms, scan_block, data)
    extra = None
    if options.latency:
        trial_options = TrialOptions(options.band, options.validation_band, options.scan_seconds,
                                     options.refine_seconds, options.feedthrough, options.min_gain)
        moved = moved_delay(pick, pick_rms, candidates, data.body, data.sweeps, data.delay, data.time_rms,
                            trial_options, lead)
        extra = 0 if moved is None else moved.extra
        if moved is not None:
            pick, pick_rms = moved.pick, moved.rms
            data = dataclasses.replace(data, body=moved.body, sweep_spectra=moved.sweep_spectra,
                                       delay=data.delay + moved.extra)
            if rang and moved.extra < 0 and pick_rms > NEAR_FLOOR * floor:
                # Behind a delay read long the scan's cores imitated a lead with poles run to z = -1, ringing in
                # simulation; refitted from them behind the shorter delay they stay far off. The scan again behind it
                # (random helmet 41, short: onset 12 for the true 10, the pick 1.03x in the sweeps' spectra and
                # 4e6x in simulation, 9.9x moved to 8 from its poles; scanned again there, 1.0x).
                pick, pick_rms, candidates = _scanned_again(pick, pick_rms, candidates, data, spectra, grid, floor)
                scan = [c.to_dict() for c in candidates]
    block, refined = _final_refinement(pick, pick_rms, data)
    # States the data did not ask for out: poles parked at the block's radius bound, states no balanced
    # realisation of the full order holds (sysid.estimation.reduction).
    validate = lambda c: data.time_rms(c, data.delay)
    refined = without_spare_pole(refined, options.band, block, validate, options.feedthrough)
    reduced = without_degenerate_states(refined.A, refined.B, refined.C, refined.D, refined.rms, block, validate,
                                        options.min_gain, options.feedthrough)
    reduced.removed = "; ".join(filter(None, [refined.removed, reduced.removed]))
    gamma = pick.gamma if pick.gamma is not None else grid_gammas.get(pick.order, grid.chosen.gamma)
    model = Model(path=data.path, fs=data.body.fs, A=reduced.A, B=reduced.B, C=reduced.C, D=reduced.D,
                  delay=data.delay,
                  identification=dict(provenance, method="latency, seed grid, then order search with output-error "
                                                         "refinement from several starts on raw DFT data",
                                      refinement={"start_gamma": gamma, "start": pick.start, "order": pick.order,
                                                  "reflected_poles": pick.reflected, "reduced": reduced.removed,
                                                  "block_seconds": block.length / data.body.fs, "order_scan": scan}))
    return model, reduced.rms, scan, extra


def _scanned_again(pick: OrderCandidate, pick_rms: float, candidates: list[OrderCandidate], data: _Behind,
                   spectra: Spectra, grid: GridResult, floor: float):
    """(pick, its time-domain rms, the scan): the order search's pick behind ``data``'s delay, settled, when it
    validates better than ``pick``; else those given."""
    block = block_data(data.body, data.options.band, data.options.scan_seconds)
    again, _ = _order_search(data, block, spectra, grid, floor, None)
    best_rms = min(c.rms for c in again)
    other = next(c for c in again if c.rms <= best_rms * (1 + data.options.min_gain))
    other, other_rms = _settle(other, data.time_rms(other, data.delay), block, data)
    return (other, other_rms, again) if other_rms < pick_rms else (pick, pick_rms, candidates)


def _order_search(data: _Behind, scan_block, spectra: Spectra, grid: GridResult, floor: float, progress):
    """(the best refined model of each order, ``order_search.search_orders`` on the scan block, and each order's
    best grid gamma)."""
    options = data.options
    # Orders given explicitly are searched as given; the seed's default 1..20 widens to SEARCH_MAX_ORDER, under the cap.
    orders = route.search_orders_of(options)
    decompositions, grid_gammas = _decompositions(spectra, grid, options.band, options.feedthrough, max(orders))
    candidates = search_orders(scan_block, data.sweep_spectra, decompositions, grid_gammas, orders, floor,
                               feedthrough=options.feedthrough, at_floor=options.at_floor, min_gain=options.min_gain,
                               progress=progress)
    return candidates, grid_gammas


def _settle(pick: OrderCandidate, pick_rms: float, block, data: _Behind) -> tuple[OrderCandidate, float]:
    """The pick with out-of-band poles run to the unit circle dropped, when that validates better in time.

    A fit on the band's bins leaves spare poles free outside it; one that runs toward z = 1 or
    z = -1 (|p| at the block's radius bound, ``output_error.decay_bound``) is invisible in the sweeps' spectra
    but rings in the simulated sweeps (random helmet 63, short session: sweeps' spectra 1.1x,
    simulation 118x; 41: 6.8e6x). While the time-domain validation rms ``pick_rms`` exceeds
    the spectra's (``pick.rms``) by more than ``min_gain``, the out-of-band pole nearest the
    unit circle is dropped (``order_search.without_freed_pole``) and the rest refitted on ``block``, up to
    ``SETTLE_DROPS`` times; the refit with the lowest time-domain rms is kept if it beats the pick's.
    """
    options = data.options
    current, best, best_rms = pick, pick, pick_rms
    current_rms = pick_rms
    for _ in range(SETTLE_DROPS):
        if current_rms <= current.rms * (1 + options.min_gain):
            break
        poles = without_freed_pole(np.linalg.eigvals(current.A), options.band, block.fs)
        if poles is None:
            break
        n = poles.size
        fit = refine_output_error(lti.real_block_diagonal(poles), np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)),
                                  block, feedthrough=options.feedthrough, max_iterations=20, noise_tolerance=True)
        current = OrderCandidate(n, pick.start + ", free pole dropped",
                                 sweep_rms(fit.A, fit.B, fit.C, fit.D, data.sweep_spectra), fit.A, fit.B, fit.C, fit.D,
                                 pick.reflected, pick.gamma)
        current_rms = data.time_rms(current, data.delay)
        if current_rms < best_rms:
            best, best_rms = current, current_rms
    return best, best_rms


def _final_refinement(pick: OrderCandidate, pick_rms: float, data: _Behind):
    """(the long block, the pick refined on it with its time-domain validation rms, or the pick itself when that
    validates better): ``refine_seconds`` of the noise recording behind the delay."""
    options = data.options
    block = block_data(data.body, options.band, options.refine_seconds)
    # Stopped once an iteration gains less than the noise can tell (output_error's noise_tolerance, as every
    # refinement here): the pick sits near the long block's minimum, and MINPACK's default tolerance crawled
    # on for 50 iterations (random helmet 5, thesis length: 18 s of CPU for 4e-6 of the cost). A pair the scan ran to
    # the real axis is refined as two real poles (output_error.split_near_real_pairs; random helmet 17: 44 -> 16
    # evaluations of the 10 s block, 1016 noise variances off the cost against 420; 11.5 -> 8.1 s of CPU).
    oe = refine_output_error(pick.A, pick.B, pick.C, pick.D, block, feedthrough=options.feedthrough, max_iterations=60,
                             noise_tolerance=True, split_near_real=True)
    rms = data.time_rms(oe, data.delay)
    if rms > pick_rms or not (at_radius_bound(np.linalg.eigvals(oe.A), block) or no_lead(oe, pick)):
        # The longer block did not help on the sweeps, or its gain out of the band grew by residues that cancel in
        # band (``sysid.estimation.delay.no_lead``; random helmet 76, short: 1.08x to 1.01x behind 63 for the true 62,
        # Hankel norm 3.8 to 40): keep the scan's model of that order. Poles parked at the block's radius bound grow
        # it too; the reduction drops those (77, short: 1.21x to 1.04x, a pole at the bound dropped after).
        return block, Reduced(pick.A, pick.B, pick.C, pick.D, pick_rms)
    return block, Reduced(oe.A, oe.B, oe.C, oe.D, rms)
