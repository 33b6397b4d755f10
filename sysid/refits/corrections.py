"""The data corrections ``refine`` applies, and the refit on the corrected data (design.md).

``add_dc_offset``, ``add_clock_drift``, ``add_clipping``: data corrections the model carries
(``output_offset``, ``clock_ratio``, ``excluded``; ``sysid.io.corrections``), each the correction
alone (``with_dc_offset``, ``with_clock_drift``, ``with_clipping``: an ``Effect.correct`` of the
registry) and, for the last two, a refit. ``correct_data`` applies several corrections and then
refits once: the core identified anew on the corrected data (every order, the latency again: the
order and delay chosen on clipped or drifting data are no bound; ``_fresh``). Excluded stretches are
filled with the prediction of the model before (``sysid.refits.machinery._prepared``), in passes
(EM, ``CLIPPING_PASSES``); where the noise recording itself has excluded stretches, the core is then
refined with them out of the output-error cost (``_gap_aware``, ``sysid.estimation.masked_output_error``);
above the floor, the core is also identified behind delays up to ``SHORTER_BY`` samples shorter
(``sysid.refits.machinery._shorter_delays``). After a clock correction the clock ratio itself is
refined from the model's residual (``clock_residual``, ``refined_clock``).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.signal

from ..core import lti
from ..core.errors import IdentificationError
from ..core.model import Model
from ..core.thresholds import (AT_FLOOR, CLIPPING_PASSES, CLOCK_AR_FLOOR, CLOCK_AR_ORDER, CLOCK_PASSES, RUN_TO_RUN_MIN,
                               WARM_ENOUGH)
from ..estimation.masked_output_error import refine_masked
from ..identify import IdentificationOptions, identify
from ..io.clipping import clipped_stretches_of
from ..io.corrections import corrected, excluded_mask, recording_key
from ..io.lines import session_lines
from ..io.recordings import Recording
from ..validation.compare import compare
from ..validation.sweeps import VALIDATION_BAND
from .machinery import (REFIT_OPTIONS, _core, _disturbance, _plain_input, _shorter_delays, _transformed, _warm,
                        _with)

__all__ = ["add_dc_offset", "add_clock_drift", "add_clipping", "with_dc_offset", "with_clock_drift", "with_clipping",
           "correct_data", "clock_residual", "refined_clock"]


def with_dc_offset(model, noise, sweeps, params):
    """The model with the ear offset added to its ``output_offset`` (FS), core kept."""
    return _with(model, _core(model), output_offset=model.output_offset + params["offset_fs"]), {}


def add_dc_offset(model, noise, sweeps, params, options, transient_s):
    # The offset is no part of the dynamics: the core stays, the prediction gains a constant. An
    # offset lies at DC, outside the identification band, so no re-identification is needed.
    return with_dc_offset(model, noise, sweeps, params)


def _fresh(model: Model, noise, sweeps, options, transient_s) -> Model:
    """The core identified anew on the model's corrected data: every order, the latency estimated again.

    A data correction changes what the order and the latency were chosen on: on clipped data
    identify stops at too low an order, and a drifting ear clock smears the onset it reads the
    latency from; so neither the model's order nor its delay bounds this refit.
    """
    recordings = _transformed(model, [noise, *sweeps], model.apply_input_nonlinearity, model.disturbance_frequencies)
    options = IdentificationOptions(**{**(options or REFIT_OPTIONS).__dict__, "transient_s": transient_s})
    core = identify(recordings[0], recordings[1:], model.path, options).model
    return _with(model, _core(core), uncertainty=core.uncertainty, delay=core.delay,
                 identification=dict(core.identification))


def _corrected_refit(trial: Model, noise, sweeps, options, transient_s) -> Model:
    """The refit behind data corrections: the better of the trial (its corrections applied, the core
    kept) and its warm start (``_warm``: the core refined by output error on the corrected noise
    recording) when that is within ``WARM_ENOUGH`` of the floor, else the core identified anew on the
    corrected data (``_fresh``).

    With excluded stretches the fresh fit runs in passes, each filling the stretches with the
    prediction of the best model so far (``_prepared``; EM for missing data: each pass a better
    model, so a better fill), until one no longer lowers the validation error by ``RUN_TO_RUN_MIN``
    or the error is at the floor. The first fill is the warm start's: the trial's core was fitted on
    the uncorrected data (a drifting clock, say) and its prediction misleads the fresh fit's ranking
    on the sweeps (the README's rig: 76x the floor at order 15 after three passes from the trial's
    fill, 1.03x at order 5 from the warm start's). The best of all is returned, after two more
    trials kept when they validate better: the core identified anew behind shorter delays (the
    latency may read long, ``_shorter_delays``), and refined with the noise recording's excluded
    samples out of the cost (``_gap_aware``).
    """
    scored = [(compare(t, sweeps), t) for t in (trial, _warm(trial, noise, options, transient_s)) if t.stable]
    # Neither stable (a warm start run unstable behind the corrections): only a fresh fit can help, and
    # without one the unstable trial goes back for the caller to refuse.
    best_after, best = min(scored, key=lambda pair: pair[0].rms) if scored else (None, trial)
    if best_after is not None and best_after.ratio <= WARM_ENOUGH:
        return best
    for _ in range(CLIPPING_PASSES if trial.excluded else 1):
        try:
            refit = _fresh(best, noise, sweeps, options, transient_s)
        except IdentificationError:
            # No stable model in the grid: the trial (or the last pass) still stands.
            break
        after = compare(refit, sweeps) if refit.stable else None
        if after is None or (best_after is not None and after.rms >= (1.0 - RUN_TO_RUN_MIN) * best_after.rms):
            break
        best, best_after = refit, after
        if after.ratio <= AT_FLOOR:
            break
    if best_after is None:
        return best
    if best_after.ratio > WARM_ENOUGH:
        # The latency read again on the corrected data may still read long (``_shorter_delays``).
        best, best_after = _shorter_delays(best, best_after, noise, sweeps, options, transient_s)
    if best_after.ratio > WARM_ENOUGH:
        # The fills above hold the last model's prediction; where the noise recording itself has gaps,
        # its core refitted with the gaps out of the cost instead (``_gap_aware``), kept if it validates better.
        polished = _gap_aware(best, noise, options, transient_s)
        if polished is not None and polished.stable and compare(polished, sweeps).rms < best_after.rms:
            best = polished
    return best


def _gap_aware(model: Model, noise: Recording, options, transient_s) -> Model | None:
    """The model's core refined by output error over the kept samples of its noise recording
    (``sysid.estimation.masked_output_error``: the excluded stretches out of the cost, not filled with a
    prediction), on the first ``refine_seconds`` after the transient; None when the noise recording
    has no excluded stretch.

    The fill of ``_prepared`` is the E step of EM for missing data, and each pass of
    ``_corrected_refit`` an M step: EM converges at the rate of the missing information, and a
    clipped noise recording misses its loudest samples, a margin around each (a noise recording
    clipped at 2 % of its samples, random helmet 101 FB: 2.3 % to 63 % excluded by margins of 0 to 2 ms,
    the filled refit 1.18x to 6.7x the floor against 1.06x unclipped).
    """
    recording = corrected(noise, model.clock_ratio)
    mask = excluded_mask(recording, model.excluded)
    if not mask.any():
        return None
    first = int(round(transient_s * recording.fs))
    stop = min(first + int(round((options or REFIT_OPTIONS).refine_seconds * recording.fs)), recording.u.size)
    keep = ~mask
    # The lines fitted where the ear signal counts; the states run from the recording's first sample (at rest).
    y = recording.y - model.output_offset - _disturbance(model, recording, model.disturbance_frequencies, keep)
    keep = keep[:stop].copy()
    keep[:first] = False
    if np.count_nonzero(keep) < 10 * (model.order + 1):
        return None
    fit = refine_masked(model.A, _plain_input(model)(recording.u)[:stop], y[:stop], keep,
                        feedthrough=bool(model.D[0, 0]))
    return _with(model, lti.balanced_realisation(fit.A, fit.B, fit.C, fit.D))


def with_clock_drift(model, noise, sweeps, params):
    """The model with its ``clock_ratio`` multiplied by 1 + ppm 1e-6 (composed with any ratio it has), core kept."""
    ratio = model.clock_ratio * (1.0 + params["ppm"] * 1e-6)
    return _with(model, _core(model), clock_ratio=ratio), {"clock_ratio": ratio}


def add_clock_drift(model, noise, sweeps, params, options, transient_s):
    # The ear channel resampled by the ratio, the core identified anew on the corrected recordings
    # (the old one fitted the drift's smeared delay).
    return correct_data(model, noise, sweeps, [(with_clock_drift, params)], options, transient_s)


def with_clipping(model, noise, sweeps, params):
    """The model with the clipped stretches of every recording (either channel, any level, with margins;
    found on the ear signal as the model's clock ratio corrects it, the flat tops also against the
    model's prediction, after the session's lines are taken out of the ear signals) in its ``excluded``,
    core kept."""
    excluded = dict(model.excluded)
    fractions = []
    recordings = [corrected(recording, model.clock_ratio) for recording in (noise, *sweeps)]
    predictions = [model.simulate(recording.u) for recording in recordings]
    lines = session_lines(recordings, predictions, model.disturbance_frequencies)
    for recording, resampled, predicted in zip((noise, *sweeps), recordings, predictions):
        spans, _ = clipped_stretches_of(resampled, predicted, lines)
        if spans:
            excluded[recording_key(recording)] = spans
        fractions.append(sum(b - a for a, b in spans) / recording.duration)
    if not excluded:
        raise IdentificationError("--add clipping: no recording clips")
    return _with(model, _core(model), excluded=excluded), {"excluded_fraction": [round(f, 6) for f in fractions]}


def add_clipping(model, noise, sweeps, params, options, transient_s):
    # Clipped stretches left out of identification and validation; the core identified anew, the
    # stretches filled with the prediction of the model before, in passes (``_corrected_refit``).
    return correct_data(model, noise, sweeps, [(with_clipping, params)], options, transient_s)


def clock_residual(model: Model, noise: Recording, transient_s: float) -> float:
    """The relative error delta of the model's clock ratio, read from its residual on the noise recording.

    The ear signal corrected by r (1 + delta) is y_c[k] + delta k y_c'[k] to first order (y_c[k] =
    y(k r), ``sysid.io.corrections``), so the residual e = y_c - prediction of a model fitted on data
    corrected by r holds -delta (k - k_m) y_c'[k]: a delay growing along the recording (the model
    took in the mean delay delta k_m over the recording's body). delta is the least-squares
    coefficient of that column, with y_c' (a constant delay) beside it, both sides band-limited
    to the validation band. The segments' phase slopes (``clock_drift_finding``) read a drift of a
    few ppm; a sharp mode validated against a floor 70 dB down needs the ratio to a few 0.01 ppm
    (random helmet 100 fb: 81.68 ppm gives 1.01x the floor with the true path, 81.60 1.28x).
    """
    recording = corrected(noise, model.clock_ratio)
    first = int(round(transient_s * recording.fs))
    predicted = model.simulate(recording.u)
    residual = recording.y - predicted - _disturbance(model, recording, model.disturbance_frequencies)
    slope = np.gradient(predicted)[first:]
    k = np.arange(first, recording.y.size, dtype=float)
    band = scipy.signal.butter(4, VALIDATION_BAND, "bandpass", fs=recording.fs, output="sos")
    X = scipy.signal.sosfiltfilt(band, np.stack([slope, (k - k.mean()) * slope], axis=1), axis=0)
    e = scipy.signal.sosfiltfilt(band, residual[first:])
    # Generalised least squares: both sides through the inverse of an AR model of the residual, so
    # lines in it (hum not yet modelled) are notched out instead of moving the estimate (the test
    # rig's hum at 1e-3 FS moved 39.96 ppm to 39.72 without).
    lags = np.array([np.dot(e[: e.size - j], e[j:]) for j in range(CLOCK_AR_ORDER + 1)]) / e.size
    # A white floor CLOCK_AR_FLOOR of the residual's power under the AR model (diagonal loading) bounds
    # its gain where the band-pass left nothing, so only strong lines are notched.
    loaded = np.concatenate(([lags[0] * (1.0 + CLOCK_AR_FLOOR)], lags[1:-1]))
    ar = scipy.linalg.solve_toeplitz(loaded, lags[1:])
    whiten = np.concatenate(([1.0], -ar))
    X, e = scipy.signal.lfilter(whiten, 1.0, X, axis=0), scipy.signal.lfilter(whiten, 1.0, e)
    coef, *_ = np.linalg.lstsq(X, e, rcond=None)
    return float(-coef[1])


def refined_clock(best: Model, noise, sweeps, options, transient_s) -> Model:
    """The model with its clock ratio refined by ``clock_residual`` and its core by a warm start, in
    passes while that lowers the validation rms by more than its run-to-run noise (``refine --auto``'s
    rule; a disturbance not yet modelled, hum say, lies in the residual and moves the estimate, and it
    makes the two sweeps differ, so such a change is not kept). The best is returned."""
    best_rms = compare(best, sweeps).rms
    for _ in range(CLOCK_PASSES):
        delta = clock_residual(best, noise, transient_s)
        trial = _with(best, _core(best), clock_ratio=best.clock_ratio * (1.0 + delta))
        warm = _warm(trial, noise, options, transient_s)
        if not warm.stable:
            break
        after = compare(warm, sweeps)
        if after.rms >= best_rms - max(after.run_to_run, RUN_TO_RUN_MIN * best_rms):
            break
        best, best_rms = warm, after.rms
    return best


def correct_data(model, noise, sweeps, corrections, options, transient_s):
    """Several data corrections, then one refit: ``corrections`` is a list of (``correct``, params), each
    ``correct(model, noise, sweeps, params) -> (model, extra)`` a correction with the core kept (an
    ``Effect.correct`` of the registry), applied in the order given; returns (model, extra of all).

    Each correction re-identifying on its own would see data that still hold the others (a drifting
    clock under the clipped stretches, an offset under the clock's refit), and the order chosen there
    wanders; so all are applied first and the core is identified once on data corrected for all.
    The caller orders them: the clock first, since the others are read on the resampled ear signal.
    """
    trial, extra = model, {}
    for correct, params in corrections:
        trial, more = correct(trial, noise, sweeps, params)
        extra.update(more)
    best = _corrected_refit(trial, noise, sweeps, options, transient_s)
    if trial.clock_ratio != model.clock_ratio:
        best = refined_clock(best, noise, sweeps, options, transient_s)
        extra["clock_ratio"] = best.clock_ratio
    return best, extra
