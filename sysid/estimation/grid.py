"""The seed's grid search over smoothing width gamma and model order n (seed section 3.3.2).

For every gamma the smoothed FRF is decomposed once (one QR and one SVD) and every
order n comes from that decomposition. Unstable candidates are excluded, as in the
seed (where none is stable, their unstable poles are reflected into the unit circle
instead); the stable ones are ranked by the validation rms on both sweeps (the true RMS,
see ``validation``), evaluated in compressed form, and the best few re-evaluated
exactly.
"""

from __future__ import annotations

import csv
import io
import sys
import time
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from ..core import lti
from ..core.errors import IdentificationError
from ..core.thresholds import DEFAULT_GAMMAS, DEFAULT_ORDERS, GRID_KEEP_BEST
from ..validation.sweeps import CompressedValidation, SweepSpectrum, rms_from_responses
from .spectra import Spectra, smoothed_responses
from .subspace import SubspaceDecomposition, SubspaceFit

__all__ = ["GridResult", "Candidate", "grid_search", "terminal_progress", "parse_range"]


@dataclass
class Candidate:
    gamma: int
    order: int
    fit: SubspaceFit
    rms: float


@dataclass
class GridResult:
    """rms[i, j] for gammas[i], orders[j] (NaN where the model is unstable; where every one is, the reflected fits)."""

    gammas: np.ndarray
    orders: np.ndarray
    rms: np.ndarray
    singular_values: dict[int, np.ndarray]
    best: list[Candidate]
    stage_seconds: dict[str, float] = field(default_factory=dict)

    @property
    def chosen(self) -> Candidate:
        return self.best[0]

    def to_csv(self) -> str:
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(["gamma", "order", "stable", "rms", "chosen"])
        for i, gamma in enumerate(self.gammas):
            for j, order in enumerate(self.orders):
                value = self.rms[i, j]
                chosen = int(gamma == self.chosen.gamma and order == self.chosen.order)
                writer.writerow([int(gamma), int(order), int(np.isfinite(value)), "" if not np.isfinite(value) else f"{value:.6e}", chosen])
        return out.getvalue()


def parse_range(text: str, name: str, with_step: bool) -> tuple[int, ...]:
    """'A:B' or 'A:B:STEP' (inclusive) as a tuple of ints; a one-line error otherwise."""
    parts = text.split(":")
    try:
        numbers = [int(p) for p in parts]
    except ValueError:
        raise IdentificationError(f"{name} must look like A:B{':STEP' if with_step else ''} with whole numbers; found {text!r}") from None
    if len(numbers) == 1:
        numbers = [numbers[0], numbers[0]]
    if len(numbers) not in ((2, 3) if with_step else (2,)):
        raise IdentificationError(f"{name} must look like A:B{':STEP' if with_step else ''}; found {text!r}")
    start, stop = numbers[0], numbers[1]
    step = numbers[2] if len(numbers) == 3 else 1
    if start < 1 or stop < start or step < 1:
        raise IdentificationError(f"{name} needs 1 <= A <= B and STEP >= 1; found {text!r}")
    return tuple(range(start, stop + 1, step))


def terminal_progress(stream=None):
    """A progress callback drawing a one-line bar on a terminal; None when not a terminal."""
    stream = stream or sys.stderr
    if not stream.isatty():
        return None

    def draw(done: int, total: int, label: str = "") -> None:
        width = 30
        filled = int(width * done / max(total, 1))
        stream.write(f"\r{label:<12} [{'#' * filled}{'.' * (width - filled)}] {done}/{total}")
        if done >= total:
            stream.write("\n")
        stream.flush()

    return draw


def grid_search(spectra: Spectra, sweeps: list[SweepSpectrum], band: tuple[float, float],
                gammas=DEFAULT_GAMMAS, orders=DEFAULT_ORDERS, q: int | None = None, feedthrough: bool = False,
                keep_best: int = GRID_KEEP_BEST, progress=None) -> GridResult:
    """Evaluate every (gamma, order) candidate; see the module docstring."""
    # The matrices are small (at most 2M x 2q); BLAS threads only add overhead here.
    with threadpool_limits(limits=1, user_api="blas"):
        return _grid_search(spectra, sweeps, band, gammas, orders, q, feedthrough, keep_best, progress)


def _grid_search(spectra, sweeps, band, gammas, orders, q, feedthrough, keep_best, progress) -> GridResult:
    gammas = np.asarray(sorted(set(gammas)), dtype=int)
    orders = np.asarray(sorted(set(orders)), dtype=int)
    q = q or max(30, int(orders.max()) + 2)
    limit = spectra.nperseg // 2
    if gammas.max() > limit:
        raise IdentificationError(f"gamma {gammas.max()} exceeds half the segment length ({limit} samples)")
    validation = CompressedValidation(sweeps)
    z_coarse = np.exp(2j * np.pi * validation.frequencies / spectra.fs)
    rms = np.full((gammas.size, orders.size), np.nan)
    singular_values = {}
    fits: dict[tuple[int, int], SubspaceFit] = {}
    seconds = {"smoothing": 0.0, "subspace": 0.0, "validation": 0.0}
    decompositions = []
    t0 = time.perf_counter()
    responses_smoothed = smoothed_responses(spectra, gammas, band)
    seconds["smoothing"] += time.perf_counter() - t0
    for i, (gamma, frf) in enumerate(zip(gammas, responses_smoothed)):
        t1 = time.perf_counter()
        decomposition = SubspaceDecomposition(2 * np.pi * frf.frequencies / spectra.fs, frf.g, q=q, feedthrough=feedthrough)
        singular_values[int(gamma)] = decomposition.singular_values
        decompositions.append(decomposition)
        seconds["subspace"] += time.perf_counter() - t1
        if progress:
            progress(i + 1, gammas.size + orders.size, "grid search")
    # Every order at every width, one order at a time: the widths' fits of one order are batched
    # (``SubspaceDecomposition.fits_if_stable``), and so are their responses on the coarse grid.
    for j, order in enumerate(orders):
        t1 = time.perf_counter()
        stable = [(i, fit) for i, fit in enumerate(SubspaceDecomposition.fits_if_stable(decompositions, int(order)))
                  if fit is not None]
        modal = [(i, fit) for i, fit in stable if fit.residues is not None]
        responses = {}
        if modal:
            g = lti.pole_residue_response(np.stack([fit.poles for _, fit in modal]), np.stack([fit.residues for _, fit in modal]),
                                          np.array([fit.D[0, 0] for _, fit in modal]), z_coarse)
            responses.update((i, row) for (i, _), row in zip(modal, g))
        for i, fit in stable:
            if fit.residues is None:
                responses[i] = lti.frequency_response(fit.A, fit.B, fit.C, fit.D, z_coarse)
            fits[(int(gammas[i]), int(order))] = fit
        t2 = time.perf_counter()
        if responses:
            rows = sorted(responses)
            rms[rows, j] = validation.rms(np.array([responses[i] for i in rows]))
        seconds["subspace"] += t2 - t1
        seconds["validation"] += time.perf_counter() - t2
        if progress:
            progress(gammas.size + j + 1, gammas.size + orders.size, "grid search")
    if not np.any(np.isfinite(rms)):
        # No candidate is stable (a fixed order on a session whose clock drifts: the phase of the high band
        # bends): each candidate's unstable poles reflected into the circle (``subspace.stabilise``) rather
        # than refusing the session; output-error refinement starts from the best of them.
        for j, order in enumerate(orders):
            for i, decomposition in enumerate(decompositions):
                if 1 <= order <= decomposition.max_order:
                    fit = decomposition.fit(int(order), "reflect")
                    fits[(int(gammas[i]), int(order))] = fit
                    rms[i, j] = validation.rms(lti.frequency_response(fit.A, fit.B, fit.C, fit.D, z_coarse)[None])[0]
    if not np.any(np.isfinite(rms)):
        raise IdentificationError("no model in the grid; widen --orders or --gammas")
    # Re-evaluate the best candidates exactly at every sweep bin.
    t0 = time.perf_counter()
    flat = np.argsort(np.where(np.isfinite(rms), rms, np.inf), axis=None)[:keep_best]
    best = []
    # Repeats of one sweep share their bins: each distinct set of bins is evaluated once.
    bins: list[SweepSpectrum] = []
    which = []
    for s in sweeps:
        same = [k for k, t in enumerate(bins) if t.fs == s.fs and np.array_equal(t.frequencies, s.frequencies)]
        if not same:
            bins.append(s)
        which.append(same[0] if same else len(bins) - 1)
    for index in flat:
        i, j = np.unravel_index(index, rms.shape)
        if not np.isfinite(rms[i, j]):
            break
        fit = fits[(int(gammas[i]), int(orders[j]))]
        responses = [lti.frequency_response(fit.A, fit.B, fit.C, fit.D, np.exp(2j * np.pi * s.frequencies / s.fs)) for s in bins]
        exact = rms_from_responses(sweeps, [responses[k] for k in which])
        best.append(Candidate(int(gammas[i]), int(orders[j]), fit, exact))
    best.sort(key=lambda c: c.rms)
    seconds["validation"] += time.perf_counter() - t0
    return GridResult(gammas, orders, rms, singular_values, best, seconds)
