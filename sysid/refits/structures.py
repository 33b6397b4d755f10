"""The structures ``refine`` adds in front of or around the core, one builder per effect (design.md).

Each builder ``add_X(model, noise, sweeps, params, options, transient_s)`` returns (the refined
model, extra parameters for its history entry); the effect registry (``sysid.effects``) names the
builder of each effect. The model chain is [input polynomial] -> [z^-delay] -> (A, B, C, D):

- ``add_delay``: more samples of pure delay; the LTI core is re-identified on the
  delayed input.
- ``add_input_nonlinearity``: a Hammerstein input map (a polynomial of the degree the data
  ask for, or a tanh saturation), refined together with the core by output error on the
  noise recording (``sysid.estimation.hammerstein``; over the samples outside the model's excluded
  stretches only, where the clipping step left some out), and, when that leaves the model above
  the floor, behind a high-pass pre-filter whose corner is fitted with them (Wiener-Hammerstein,
  ``sysid.estimation.wiener_hammerstein``); the core re-identified behind the map when that
  does not reach the floor; then its order chosen again on the compensated problem
  (``sysid.refits.nonlinear_order``: the order read on the nonlinear data took harmonics for dynamics).
- ``add_periodic_disturbance``: sinusoids at given frequencies, fitted per recording
  and removed from the ear signal before the fit; kept in the model's disturbance
  (not part of the plant) and removed again by ``compare``.
- ``series_factor(coefficients)``: a fixed factor (``sysid.core.structures``) in series in
  front of the core (high-pass, low-pass, peaking resonance, a user's own factor);
  the core is refined by output error with the factor as a prefilter, and
  re-identified from scratch when that does not reach the noise floor (the better
  on the sweeps is kept); the product becomes (A, B, C, D).
- ``add_mode``: one more mode (2 states) started at f0, Q, all poles refined by output
  error on the raw DFT data (a resonance given without its gain).
- ``add_order``: more order, as modes started at the bands worst against the noise
  floor (``sysid.validation.compare.worst_bands``) and refined by output error, or as a
  fresh fit up to the higher order.
- ``add_input_noise``: the errors-in-variables estimator: the output-error fit on the ear
  DFT divided by the H1 attenuation 1 - P_n / S_uu, P_n the input noise density measured
  from the repeated sweeps.

The warm starts and re-identifications are the refit machinery's (``sysid.refits.machinery``).
"""

from __future__ import annotations

import numpy as np
import scipy.signal

from ..core.errors import IdentificationError, ModelError
from ..core.model import Model
from ..core.structures import factor_coefficients, factor_response, mode_block, series, tf_to_statespace, with_states
from ..core.thresholds import AT_FLOOR, CLIPPING_PASSES, EIV_MIN_ATTENUATION, RUN_TO_RUN_MIN
from ..estimation.delay import delay_totals
from ..estimation.hammerstein import fit_hammerstein
from ..estimation.input_nonlinearity import drive_limit
from ..estimation.input_polynomial import input_polynomial
from ..estimation.wiener_hammerstein import fit_wiener_hammerstein
from ..findings.context import detector_context
from ..io.recordings import Recording
from ..estimation.output_error import BlockData, refine_output_error
from ..validation.compare import START_Q, compare, worst_bands
from .machinery import (REFIT_OPTIONS, _core, _core_body, _disturbance, _kept, _output_error_data, _plain_input,
                        _prepared, _refit, _reidentify, _shift, _unmasked_delay, _warm, _with)
from .nonlinear_order import fewest_states

# The noise recording's stretch (s) the Hammerstein refinement fits the map on (the core: the refit's
# refine_seconds), and the orders above the model's a core identified anew behind the input map may take.
HAMMERSTEIN_SECONDS = 2.0
MAX_ORDER_SEARCH = 20

__all__ = ["add_delay", "add_input_nonlinearity", "add_periodic_disturbance", "series_factor", "add_resonance",
           "add_highpass", "add_lowpass", "add_mode", "add_order", "add_input_noise"]


def add_delay(model, noise, sweeps, params, options, transient_s):
    # The total and one sample less (``sysid.estimation.delay.delay_totals``); warm starts behind both delays
    # first, re-identifications only when neither reaches the floor.
    totals = delay_totals(model.delay, params["samples"])
    warm = [t for t in (_warm(_with(model, _core(model), delay=total), noise, options, transient_s) for total in totals)
            if t.stable]

    def reidentify():
        fresh = []
        for total in totals:
            core = _reidentify(model, noise, sweeps, lambda u: _shift(model.apply_input_nonlinearity(u), total),
                               model.disturbance_frequencies, options, transient_s)
            fresh.append(_with(model, _core(core), uncertainty=core.uncertainty,
                               delay=total + core.delay, identification=dict(core.identification)))
        stable = [t for t in fresh if t.stable]
        return min(stable, key=lambda t: compare(t, sweeps).rms) if stable else fresh[0]

    best = _refit(sweeps, warm, reidentify)
    if not best.stable:
        raise IdentificationError(f"refining with delay {model.delay + params['samples']} gave no stable model")
    return best, {"total_samples": best.delay}


def add_input_nonlinearity(model, noise, sweeps, params, options, transient_s):
    """The Hammerstein input map the data ask for, fitted with the core (``sysid.estimation.hammerstein``).

    Each shape (``params["shape"]``: "polynomial", "tanh" or "auto", both) is refined together with the
    current core, which keeps its order; when none reaches the floor the core is identified anew behind the
    best map (every order: the order chosen on the nonlinear data fitted harmonics or missed modes they hid)
    and refined with the map again. The shape of lowest validation rms is kept (``_refit``), and its core
    truncated to the fewest states that, refitted with the map, validate as well
    (``sysid.refits.nonlinear_order.fewest_states``): neither the order identified on the distorted session
    nor the re-identification's (the order of lowest validation rms, up to ``MAX_ORDER_SEARCH`` above) is a
    bound on what the plant holds once the map takes the harmonics.
    """
    recording = _raw_recording(model, noise)
    # The clipped stretches the model leaves out (its ``excluded``, the clipping step's) stay out of the map's
    # and the core's fit: the fill of ``_prepared`` is the linear model's, without the harmonics and the DC the
    # map makes (the seed's FB path, DC gain 738 against 23.5 in band: u^2 clips the ear channel).
    keep = _kept(model, noise)
    shapes = ("polynomial", "tanh") if params.get("shape", "auto") == "auto" else (params["shape"],)
    core_seconds = (options or REFIT_OPTIONS).refine_seconds

    def joint(start, shape):
        # A shape that fails (no stable core; a polynomial whose coefficients in FS units pass the model's
        # limits: degree 7 on a drive of 0.07 FS peak, the seed's FB path) leaves the others.
        try:
            fit = fit_hammerstein(start, recording, shape, min(core_seconds, HAMMERSTEIN_SECONDS), core_seconds,
                                  transient_s, max_degree=params["degree"],
                                  prefilter=(start.input_nonlinearity_form or {}).get("prefilter"), keep=keep)
            return _with(start, (fit.A, fit.B, fit.C, fit.D), input_nonlinearity=fit.coefficients,
                         input_nonlinearity_form=fit.form)
        except (IdentificationError, ModelError):
            return None

    trials = [t for t in (joint(model, shape) for shape in shapes) if t is not None and t.stable]
    # And the cubic read on the sweep residual through the current linear part, the core refined behind it
    # (the diagnosis's estimator): from a core far off, the alternation can settle short of it (the seed's
    # FF path with a delay of 23 and H2 = H3 = -35 dB: 1.31x the floor against 1.2x).
    ctx = detector_context(model, noise, sweeps, compare(model, sweeps), transient_s)
    found = input_polynomial(ctx.model, ctx.sweeps, ctx.comparison.per_sweep)
    previous = model.input_nonlinearity or [1.0]
    added = [0.0, float(found.a2), float(found.a3)]
    cubic = [float(a + b) for a, b in zip(previous + [0.0] * (3 - len(previous)), added)] + previous[3:]
    try:
        residual_trial = _warm(_with(model, _core(model), input_nonlinearity=cubic), noise, options, transient_s)
        trials += [residual_trial] if residual_trial.stable else []
    except (IdentificationError, ModelError):
        pass
    if not trials:
        raise IdentificationError("the Hammerstein refinement gave no stable model")
    statics = list(trials)
    # The Wiener-Hammerstein variant only where the static maps leave the model above the floor (and it has no
    # pre-filter yet: a second refinement refits the one it has).
    wiener = _above_floor(statics, sweeps) and not (model.input_nonlinearity_form or {}).get("prefilter")
    if wiener:
        trials += _wiener_hammerstein(model, recording, sweeps, statics, params, core_seconds, transient_s, joint,
                                      keep)

    def reidentify():
        # Behind the map and the model's delay (identify adds what latency it reads beyond), and behind the
        # map alone with the delay read anew (the one read on the nonlinear data may be off); every order.
        # With the variant, the core is identified behind the best static map (the pre-filter's linear part
        # taken in, as by the first identification) and the pre-filter searched again from it: a corner
        # found from a core short of the plant's order is off (random helmet 11 FB, 3 states for 6, behind
        # a 20 Hz high-pass: second order at 14 Hz, 55x the floor).
        best = min(statics if wiener else trials, key=lambda t: compare(t, sweeps).rms)
        best_rms = compare(best, sweeps).rms
        fresh = []  # (validation, core) of every core found behind the map
        # Where the noise recording has excluded stretches, identify reads them filled with the prediction of
        # the model it starts from (``_prepared``): a core short of the path (identified on the clipped data)
        # fills them short of the DC and the harmonics the map makes, and is found again. So the fit runs in
        # passes, as the clipping step's own refit does (EM for missing data: each pass fills with the best
        # model behind the map so far), until one no longer lowers the validation error or reaches the floor.
        passes = CLIPPING_PASSES if not keep.all() else 1
        for _ in range(passes):
            found = [(compare(t, sweeps), t) for t in fresh_behind(best)]
            fresh += found
            if not found:
                break
            top_validation, top = min(found, key=lambda f: f[0].rms)
            if top_validation.ratio <= AT_FLOOR or top_validation.rms >= (1.0 - RUN_TO_RUN_MIN) * best_rms:
                break
            best, best_rms = top, top_validation.rms
        if not fresh:
            raise IdentificationError("no stable core behind the input map")
        return min(fresh, key=lambda f: f[0].rms)[1]

    def fresh_behind(best):
        fresh = []
        for input_map, delay in ((_plain_input(best), best.delay), (best.apply_input_nonlinearity, 0)):
            try:
                core = _reidentify(best, noise, sweeps, input_map, model.disturbance_frequencies, options,
                                   transient_s, extra_order=MAX_ORDER_SEARCH, min_order=1)
            except IdentificationError:
                continue
            start = _with(best, _core(core), uncertainty=core.uncertainty, delay=delay + core.delay,
                          identification=dict(core.identification))
            behind = [t for t in (start, *(joint(start, shape) for shape in shapes)) if t is not None and t.stable]
            fresh += behind
            if wiener and behind and _above_floor(behind, sweeps):
                fresh += _wiener_hammerstein(start, recording, sweeps, behind, params, core_seconds, transient_s, joint,
                                             keep)
        return fresh

    best = _refit(sweeps, trials, reidentify)
    unmasked = _unmasked_delay(best, noise, sweeps, options, transient_s)
    if wiener and unmasked.delay != best.delay and _above_floor([unmasked], sweeps) and \
            (unmasked.input_nonlinearity_form or {}).get("prefilter"):
        # A core identified anew behind another delay: the corner found for the old one is searched again.
        unmasked = min([unmasked, *_wiener_hammerstein(unmasked, recording, sweeps, [unmasked], params, core_seconds,
                                                        transient_s, joint, keep)], key=lambda t: compare(t, sweeps).rms)
    # The order the compensated data hold: the order read on the nonlinear data took harmonics for dynamics.
    shape = "tanh" if (unmasked.input_nonlinearity_form or {}).get("kind") == "tanh" else "polynomial"
    best, _ = fewest_states(unmasked, sweeps, lambda start: joint(start, shape))
    # The drive a controller may command (sysid.estimation.input_nonlinearity.drive_limit), in the provenance.
    best.identification["drive_limit_fs"] = drive_limit(best)
    form = best.input_nonlinearity_form or {}
    shape = {"form": form} if form.get("kind") == "tanh" else {"coefficients": best.input_nonlinearity}
    return best, {"shape": "tanh" if form.get("kind") == "tanh" else "polynomial", **shape,
                  **({"prefilter": form["prefilter"]} if form.get("prefilter") else {}), "order": best.order,
                  "drive_limit_fs": best.identification["drive_limit_fs"]}


def _above_floor(trials, sweeps) -> bool:
    return min(compare(t, sweeps).ratio for t in trials) > AT_FLOOR


def _wiener_hammerstein(model, recording, sweeps, trials, params, core_seconds, transient_s, joint, keep=None) -> list:
    """The Wiener-Hammerstein trials (``sysid.estimation.wiener_hammerstein``: a high-pass in front of the map,
    its corner fitted with the map and ``model``'s core; the saturation refitted behind the pre-filter found),
    each kept only when it lowers the validation rms of the static ``trials`` by more than its run-to-run
    noise (the clean and the static drivers keep their static map)."""
    static = min((compare(t, sweeps) for t in trials), key=lambda c: c.rms)
    try:
        fit = fit_wiener_hammerstein(model, recording, "polynomial", min(core_seconds, HAMMERSTEIN_SECONDS),
                                     core_seconds, transient_s, max_degree=params["degree"], keep=keep)
        found = _with(model, (fit.A, fit.B, fit.C, fit.D), input_nonlinearity=fit.coefficients,
                      input_nonlinearity_form=fit.form)
    except (IdentificationError, ModelError):
        return []
    saturating = joint(_with(model, _core(model), input_nonlinearity_form={"kind": "identity", "prefilter":
                                                                            fit.form["prefilter"]}), "tanh")
    kept = []
    for trial in (found, saturating):
        if trial is not None and trial.stable:
            after = compare(trial, sweeps)
            if after.rms < static.rms - max(static.run_to_run, RUN_TO_RUN_MIN * static.rms):
                kept.append(trial)
    return kept


def _raw_recording(model, noise) -> Recording:
    """The noise recording as the model's input map sees it: the raw input, the ear signal without the model's
    disturbance and output offset (``sysid.refits.machinery._core_body`` before the map, the transient kept)."""
    prepared = _prepared(model, noise)
    y = prepared.y - model.output_offset - _disturbance(model, prepared, model.disturbance_frequencies,
                                                        _kept(model, noise))
    return Recording(prepared.u, y, prepared.fs, prepared.path)


def add_periodic_disturbance(model, noise, sweeps, params, options, transient_s):
    frequencies = sorted(set((model.disturbance_frequencies or []) + list(params["frequencies_hz"])))
    kept = _with(model, _core(model), disturbance_frequencies=frequencies)

    def reidentify():
        core = _reidentify(model, noise, sweeps, _plain_input(model),
                           frequencies, options, transient_s)
        return _with(model, _core(core), uncertainty=core.uncertainty, delay=model.delay + core.delay,
                     disturbance_frequencies=frequencies, identification=dict(core.identification))
    # The core kept is among the trials: a disturbance model that keeps the core can only lower the error.
    best = _refit(sweeps, [kept, _warm(kept, noise, options, transient_s)], reidentify)
    return _unmasked_delay(best, noise, sweeps, options, transient_s), {"frequencies_hz": frequencies}


def add_order(model, noise, sweeps, params, options, transient_s):
    """More order: modes added at the worst bands and refined, or a fresh fit up to the higher order."""
    extra = params["extra_order"]
    data = _output_error_data(model, noise, transient_s, (options or REFIT_OPTIONS).refine_seconds)
    blocks = [mode_block(r["center_hz"], START_Q, model.fs) for r in worst_bands(compare(model, sweeps), extra // 2)]
    if extra % 2:
        blocks.append(np.array([[0.9]]))
    grown = _grown(model, data, blocks)

    def reidentify():
        core = _reidentify(model, noise, sweeps, _plain_input(model),
                           model.disturbance_frequencies, options, transient_s, extra_order=extra)
        return _with(model, _core(core), uncertainty=core.uncertainty,
                     delay=model.delay + core.delay, identification=dict(core.identification))
    best = _refit(sweeps, [grown], reidentify)
    return best, {"order": best.order}


def _grown(model, data, blocks) -> Model:
    """The model with new state blocks, all poles and zeros refined by output error on data."""
    A, B, C = with_states(model.A, model.B, model.C, *blocks)
    oe = refine_output_error(A, B, C, model.D, data, delay=model.delay, feedthrough=bool(model.D[0, 0]))
    return _with(model, (oe.A, oe.B, oe.C, oe.D))


def series_factor(coefficients):
    """The builder of a fixed factor in series in front of the core; ``coefficients(params, fs) -> (b, a)``."""
    def build(model, noise, sweeps, params, options, transient_s):
        b, a = coefficients(params, model.fs)
        factor = tf_to_statespace(b, a)
        data = _output_error_data(model, noise, transient_s, (options or REFIT_OPTIONS).refine_seconds)
        prefilter = factor_response(b, a, np.angle(data.z) * model.fs / (2 * np.pi), model.fs)
        oe = refine_output_error(model.A, model.B, model.C, model.D, data, delay=model.delay,
                                 feedthrough=bool(model.D[0, 0]), prefilter=prefilter)
        # The core kept as it is, and refined behind the factor; the better on the sweeps is kept.
        trials = [_with(model, series(factor, _core(model))), _with(model, series(factor, (oe.A, oe.B, oe.C, oe.D)))]
        scored = sorted((compare(t, sweeps).ratio, k) for k, t in enumerate(trials) if t.stable)
        if not scored or scored[0][0] > AT_FLOOR:
            # Not at the floor: either the core was bent to mimic the factor (a fresh core behind
            # the factor fixes that), or another effect is left, which a fresh core would partly
            # take in and so hide from the next diagnosis. Only a fresh core at the floor is kept.
            # A fresh core behind the factor may need fewer states: the old core had taken the factor in.
            core = _reidentify(model, noise, sweeps,
                               lambda u: scipy.signal.lfilter(b, a, _shift(model.apply_input_nonlinearity(u), model.delay)),
                               model.disturbance_frequencies, options, transient_s, min_order=1)
            fresh = _with(model, series(factor, _core(core)), uncertainty=core.uncertainty,
                          delay=model.delay + core.delay, identification=dict(core.identification))
            ratio = compare(fresh, sweeps).ratio if fresh.stable else np.inf
            if ratio <= AT_FLOOR or not scored:
                trials.append(fresh)
                scored = [(ratio, len(trials) - 1)]
        return trials[scored[0][1]], {"factor_order": len(a) - 1}
    return build


def add_resonance(model, noise, sweeps, params, options, transient_s):
    """A resonance: a peaking factor in series when its gain is given, else one more mode at f0, Q."""
    if params["gain_db"] is None:
        return add_mode(model, noise, sweeps, params, options, transient_s)
    return _peaking(model, noise, sweeps, params, options, transient_s)


def _factor_of(kind):
    return lambda params, fs: factor_coefficients(kind, params, fs)


_peaking = series_factor(_factor_of("resonance"))
add_highpass = series_factor(_factor_of("highpass"))
add_lowpass = series_factor(_factor_of("lowpass"))


def add_mode(model, noise, sweeps, params, options, transient_s):
    data = _output_error_data(model, noise, transient_s, (options or REFIT_OPTIONS).refine_seconds)
    grown = _grown(model, data, [mode_block(params["f0_hz"], params["q"], model.fs)])
    return grown, {"order": grown.order}


def add_input_noise(model, noise, sweeps, params, options, transient_s):
    """The errors-in-variables estimate: the output-error fit made unbiased for white input noise.

    With noise of density P_n on the measured input, least squares of Y on the measured U tends
    bin by bin to H1 = G (1 - P_n / S_uu(f)) (S_uu the measured input's density): the whole fit,
    poles and zeros, is biased low where the input SNR is low. Dividing the ear DFT by that
    attenuation, smoothed from a Welch estimate of S_uu, makes the fit's target G itself (a
    frequency-domain bias correction of H1; Pintelon & Schoukens, System Identification, 2nd
    ed., sec. 7.6: errors-in-variables with known noise variance); the final linear step is then
    left uncompensated (the correction is in the data already).
    """
    density = params["input_noise_density"]
    body = _core_body(model, noise, transient_s)
    data = _output_error_data(model, noise, transient_s, (options or REFIT_OPTIONS).refine_seconds)
    f, s_uu = scipy.signal.welch(body.u - body.u.mean(), model.fs, nperseg=2205)
    bins = np.angle(data.z) * model.fs / (2 * np.pi)
    attenuation = np.maximum(1.0 - density / np.maximum(np.interp(bins, f, s_uu), 1e-30), EIV_MIN_ATTENUATION)
    unbiased = BlockData(data.z, data.U, data.Y / attenuation, data.length, data.fs)
    oe = refine_output_error(model.A, model.B, model.C, model.D, unbiased, delay=model.delay,
                             feedthrough=bool(model.D[0, 0]))
    refined = _with(model, (oe.A, oe.B, oe.C, oe.D))
    refined.identification["estimator"] = "bias-compensated output error (errors in variables)"
    return refined, {"input_noise_density": density}
