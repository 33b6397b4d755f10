"""The identification pipeline: noise recording + two sweeps -> a stable model of one path.

1. Spectra of the noise recording after its transient (``spectra``: h1 or seed-average).
2. The seed's grid over smoothing width gamma and order n of the frequency-domain
   subspace method, ranked by the true validation rms on both sweeps (``grid``).
3. Beyond the seed (design.md, identification step 5): starting from the grid's best
   model of each order, output-error refinement on the raw DFT of the noise recording
   (``output_error``) in ascending order until more order stops paying, then the
   chosen order refined on a longer block. Both the seed's choice and the refined
   model are reported; the refined one is returned when it validates better.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .errors import IdentificationError
from .grid import DEFAULT_GAMMAS, DEFAULT_ORDERS, GridResult, grid_search
from .model import PATHS, Model
from .output_error import block_data, refine_output_error
from .recordings import Recording, check_same_rate
from .spectra import ESTIMATORS, Spectra, estimate_spectra, smoothed_response
from .subspace import SubspaceDecomposition
from .validation import VALIDATION_BAND, check_repeats, noise_floor, simulated_rms, sweep_spectrum

__all__ = ["IdentificationOptions", "Identification", "identify", "IDENTIFICATION_BAND"]

IDENTIFICATION_BAND = (20.0, 5000.0)


@dataclass(frozen=True)
class IdentificationOptions:
    """Options of ``identify``; the defaults are the seed's grid and the corrected estimator."""

    estimator: str = "h1"
    gammas: tuple[int, ...] = DEFAULT_GAMMAS
    orders: tuple[int, ...] = DEFAULT_ORDERS
    band: tuple[float, float] = IDENTIFICATION_BAND
    validation_band: tuple[float, float] = VALIDATION_BAND
    transient_s: float = 3.0
    feedthrough: bool = False
    refine: bool = True
    scan_seconds: float = 0.5
    refine_seconds: float = 10.0
    # Stop raising the order once this many successive orders improve the rms by < min_gain.
    patience: int = 2
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


def _check_inputs(noise: Recording, sweeps: list[Recording], options: IdentificationOptions) -> None:
    if options.estimator not in ESTIMATORS:
        raise IdentificationError(f"estimator must be one of {', '.join(ESTIMATORS)}; found {options.estimator!r}")
    if len(sweeps) != 2:
        raise IdentificationError(f"need exactly two validation sweeps; found {len(sweeps)}")
    check_same_rate([noise, *sweeps])
    check_repeats(*sweeps)


def identify(noise: Recording, sweeps: list[Recording], path: str = "fb",
             options: IdentificationOptions | None = None, progress=None) -> Identification:
    """Identify a stable model of ``path`` from a noise recording and two sweeps."""
    options = options or IdentificationOptions()
    if path not in PATHS:
        raise IdentificationError(f"path must be one of {', '.join(PATHS)}; found {path!r}")
    _check_inputs(noise, sweeps, options)
    fs = noise.fs
    seconds: dict[str, float] = {}

    t0 = time.perf_counter()
    body = noise.trimmed(options.transient_s)
    spectra = estimate_spectra(body, options.estimator)
    sweep_spectra = [sweep_spectrum(s, options.validation_band) for s in sweeps]
    floor = noise_floor(sweeps[0], sweeps[1], options.validation_band)
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
        "grid": {"gammas": [int(grid.gammas[0]), int(grid.gammas[-1])], "orders": [int(grid.orders[0]), int(grid.orders[-1])],
                 "candidates": int(grid.rms.size), "stable": int(np.isfinite(grid.rms).sum())},
        "seed_choice": {"gamma": chosen.gamma, "order": chosen.order},
        "noise_floor": floor,
    }
    seed_model = Model(path=path, fs=fs, A=chosen.fit.A, B=chosen.fit.B, C=chosen.fit.C, D=chosen.fit.D,
                       identification=dict(provenance, method="seed grid (smoothed FRF + subspace)"))
    seed_rms = simulated_rms(seed_model, sweeps, options.validation_band)
    provenance["seed_choice"]["rms"] = seed_rms

    result_model, refined_rms, scan = seed_model, None, []
    if options.refine:
        t0 = time.perf_counter()
        result_model, refined_rms, scan = _refine(body, sweeps, spectra, grid, path, options, provenance, progress)
        seconds["refinement"] = time.perf_counter() - t0
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
        "rms": final_rms,
        "noise_floor": floor,
        "refined": result_model is not seed_model,
    })
    return Identification(result_model, grid, spectra, floor, seed_model, seed_rms, refined_rms, scan, seconds)


def _best_fit_per_order(spectra: Spectra, grid: GridResult, band, feedthrough: bool):
    """For each order with a stable candidate: (order, gamma, grid rms, fit) of its best gamma."""
    decompositions = {}
    out = []
    for j, order in enumerate(grid.orders):
        column = grid.rms[:, j]
        if not np.any(np.isfinite(column)):
            continue
        i = int(np.nanargmin(column))
        gamma = int(grid.gammas[i])
        if gamma not in decompositions:
            frf = smoothed_response(spectra, gamma, band)
            decompositions[gamma] = SubspaceDecomposition(2 * np.pi * frf.frequencies / spectra.fs, frf.g,
                                                          q=max(30, int(grid.orders.max()) + 2), feedthrough=feedthrough)
        out.append((int(order), gamma, float(column[i]), decompositions[gamma]))
    return out


def _refine(body, sweeps, spectra, grid, path, options, provenance, progress):
    scan_block = block_data(body, options.band, options.scan_seconds)
    candidates = _best_fit_per_order(spectra, grid, options.band, options.feedthrough)
    scan = []
    best_rms = np.inf
    stalls = 0
    for k, (order, gamma, grid_rms, decomposition) in enumerate(candidates):
        fit = decomposition.fit_if_stable(order)
        oe = refine_output_error(fit.A, fit.B, fit.C, fit.D, scan_block, feedthrough=options.feedthrough, max_iterations=30)
        trial = Model(path=path, fs=body.fs, A=oe.A, B=oe.B, C=oe.C, D=oe.D)
        rms = simulated_rms(trial, sweeps, options.validation_band)
        scan.append({"order": order, "gamma": gamma, "grid_rms": grid_rms, "refined_rms": rms})
        if progress:
            progress(k + 1, len(candidates), "order scan")
        if rms < best_rms * (1 - options.min_gain):
            stalls = 0
        else:
            stalls += 1
        best_rms = min(best_rms, rms)
        if stalls >= options.patience:
            break
    if progress and scan and len(scan) < len(candidates):
        progress(len(candidates), len(candidates), "order scan")
    # The lowest order within min_gain of the best refined rms.
    threshold = best_rms * (1 + options.min_gain)
    pick = next(entry for entry in scan if entry["refined_rms"] <= threshold)
    order, gamma = pick["order"], pick["gamma"]
    decomposition = next(c[3] for c in candidates if c[0] == order)
    fit = decomposition.fit_if_stable(order)
    block = block_data(body, options.band, options.refine_seconds)
    oe = refine_output_error(fit.A, fit.B, fit.C, fit.D, block, feedthrough=options.feedthrough, max_iterations=60)
    model = Model(path=path, fs=body.fs, A=oe.A, B=oe.B, C=oe.C, D=oe.D,
                  identification=dict(provenance, method="seed grid, then output-error refinement on raw DFT data",
                                      refinement={"start_gamma": gamma, "order": order, "block_seconds": block.length / body.fs,
                                                  "order_scan": scan}))
    return model, simulated_rms(model, sweeps, options.validation_band), scan
