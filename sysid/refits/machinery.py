"""The refit machinery every structure and correction of ``refine`` shares: warm starts and re-identifications.

A refit sees the recordings as the model's core does (``_transformed``: the model's data corrections
applied, its input map, its disturbance and output offset out of the ear signal). Every
re-identification fits the core behind the model's own delay and input map, and runs only when the
warm start (``_warm``: the current core, its order, poles and zeros, refined by output error behind
the new structure) and the structure with the core kept do not come within ``WARM_ENOUGH`` of the
noise floor (``_refit``): the re-identification's grid and order search are most of a step's time.
Where a step leaves the model above that, the delay may have read long: the core is identified anew
behind shorter delays (``_shorter_delays``, the rule in ``sysid.estimation.delay.shorter_delays``).
"""

from __future__ import annotations

import numpy as np

from ..core.errors import IdentificationError
from ..core.model import Model
from ..core.thresholds import IDENTIFICATION_BAND, WARM_ENOUGH
from ..estimation.delay import shorter_delays
from ..estimation.output_error import block_data, refine_output_error
from ..estimation.spectra import estimate_spectra
from ..estimation.uncertainty import frequency_response_band
from ..identify import IdentificationOptions, identify
from ..io.corrections import corrected, excluded_mask
from ..io.lines import fit_sinusoids
from ..io.recordings import Recording
from ..validation.compare import compare

__all__ = ["REFIT_OPTIONS", "WARM_ENOUGH"]


# The re-identification's grid: the seed's orders, gamma step 30 (as the test sessions use).
REFIT_OPTIONS = IdentificationOptions(gammas=tuple(range(10, 1001, 30)), refine_seconds=5.0)


def _shift(x: np.ndarray, d: int) -> np.ndarray:
    return np.concatenate((np.zeros(min(d, x.size)), x[: max(x.size - d, 0)])) if d else x


def _plain_input(model):
    """The model's input map: its input polynomial, then its delay."""
    return lambda u: _shift(model.apply_input_nonlinearity(u), model.delay)


def _disturbance(model: Model, recording: Recording, frequencies, keep: np.ndarray | None = None) -> np.ndarray:
    """Sinusoids at frequencies fitted to the recording's residual under ``model`` (over the ``keep``
    samples: outside the excluded stretches, where the prediction fills in for the ear signal)."""
    if not frequencies:
        return np.zeros_like(recording.y)
    return fit_sinusoids(recording.y - model.simulate(recording.u), frequencies, recording.fs, keep=keep)


def _prepared(model: Model, recording: Recording) -> Recording:
    """A recording with the model's data corrections: ear clock resampled, excluded stretches left out.

    The ear signal inside an excluded stretch is replaced by the model's prediction (the
    expectation of a missing sample given the model: the E step of EM for missing data), so
    the stretch adds no information of its own. Cutting the stretches out and joining the
    parts instead leaves a transient of the impulse response at every joint: on a preamplifier
    that flat-tops every few hundred samples that misfit outweighs the plant.
    """
    recording = corrected(recording, model.clock_ratio)
    mask = excluded_mask(recording, model.excluded)
    if not mask.any():
        return recording
    y = recording.y.copy()
    y[mask] = model.simulate(recording.u)[mask]
    return Recording(recording.u, y, recording.fs, recording.path, recording.clipped_fraction, recording.dc_offset)


def _kept(model: Model, recording: Recording) -> np.ndarray:
    """True at the samples of the recording (its ear clock corrected) outside the model's excluded stretches."""
    return ~excluded_mask(corrected(recording, model.clock_ratio), model.excluded)


def _transformed(model, recordings, input_map, frequencies) -> list[Recording]:
    """Recordings as the LTI core sees them: data corrections applied, mapped input, ear signal
    without the disturbance and the output offset."""
    prepared = [_prepared(model, r) for r in recordings]
    kept = [_kept(model, r) for r in recordings]
    return [Recording(input_map(r.u), r.y - model.output_offset - _disturbance(model, r, frequencies, keep), r.fs,
                      r.path) for r, keep in zip(prepared, kept)]


def _reidentify(model, noise, sweeps, input_map, frequencies, options, transient_s, extra_order: int = 2,
                min_order: int | None = None) -> Model:
    recordings = _transformed(model, [noise, *sweeps], input_map, frequencies)
    options = options or REFIT_OPTIONS
    # Orders from the model's (an added structure does not take dynamics away: a lower order chosen
    # against a floor that an unmodelled effect inflates leaves the model short once the effect is
    # modelled) to two above it (the added structure, not more order, should explain the data).
    min_order = model.order if min_order is None else min_order
    orders = tuple(n for n in options.orders if min_order <= n <= model.order + extra_order) or (model.order,)
    # The core is fitted behind the model's own delay (input_map applies it); the latency identify
    # finds beyond it (the returned model's delay) belongs in front of the core: callers add it.
    options = IdentificationOptions(**{**options.__dict__, "transient_s": transient_s, "orders": orders})
    return identify(recordings[0], recordings[1:], model.path, options).model


def _with(model: Model, core, **changes) -> Model:
    """A copy of model with the core (A, B, C, D) and fields replaced.

    The model's uncertainty band stays only with its own core (a band belongs to the fit it
    was estimated from); a re-identified core brings its own (``uncertainty=core.uncertainty``).
    """
    A, B, C, D = core
    same_core = all(np.array_equal(a, b) for a, b in zip((A, B, C, D), (model.A, model.B, model.C, model.D)))
    fields = dict(path=model.path, fs=model.fs, A=A, B=B, C=C, D=D, delay=model.delay,
                  uncertainty=model.uncertainty if same_core else None,
                  input_nonlinearity=model.input_nonlinearity, input_nonlinearity_form=model.input_nonlinearity_form,
                  disturbance_frequencies=model.disturbance_frequencies,
                  history=list(model.history), identification=dict(model.identification),
                  output_offset=model.output_offset, clock_ratio=model.clock_ratio, excluded=dict(model.excluded))
    fields.update(changes)
    return Model(**fields)


def _core(m: Model):
    return m.A, m.B, m.C, m.D


def _warm(trial: Model, noise, options, transient_s) -> Model:
    """The trial's core (the current model's order, poles and zeros) refined by output error behind the
    trial's new structure (its delay, input polynomial, disturbance): the warm start of a refit."""
    seconds = (options or REFIT_OPTIONS).refine_seconds
    body = _core_body(trial, noise, transient_s)
    oe = refine_output_error(trial.A, trial.B, trial.C, trial.D, block_data(body, IDENTIFICATION_BAND, seconds),
                             delay=trial.delay, feedthrough=bool(trial.D[0, 0]))
    warm = _with(trial, (oe.A, oe.B, oe.C, oe.D))
    if warm.stable:
        # The refined core's own 95 % band, as identify gives a fresh core (a band belongs to its fit).
        warm.uncertainty = frequency_response_band(warm, body, estimate_spectra(body, "h1"), IDENTIFICATION_BAND,
                                                   seconds).to_dict()
    return warm


def _core_body(model, noise, transient_s) -> Recording:
    """The noise recording after its transient as the model's core sees it (``_transformed``, delay not applied)."""
    body = _prepared(model, noise).trimmed(transient_s)
    y = body.y - model.output_offset - _disturbance(model, body, model.disturbance_frequencies)
    return Recording(model.apply_input_nonlinearity(body.u), y, body.fs, body.path)


def _output_error_data(model, noise, transient_s, seconds):
    return block_data(_core_body(model, noise, transient_s), IDENTIFICATION_BAND, seconds)


def _refit(sweeps, trials: list[Model], reidentify) -> Model:
    """The stable model of lowest validation rms among ``trials`` (warm starts and the structure with
    the core kept), and ``reidentify()`` (a fresh identification behind the structure, the costly part:
    an order and grid search) only when none of them is within ``WARM_ENOUGH`` of the noise floor."""
    scored = sorted(((c.rms, c.ratio, k) for k, t in enumerate(trials) if t.stable
                     for c in [compare(t, sweeps)]), key=lambda x: x[0])
    if scored and scored[0][1] <= WARM_ENOUGH:
        return trials[scored[0][2]]
    try:
        fresh = reidentify()
    except IdentificationError:
        # No stable model in the re-identification's grid (orders bounded around the model's):
        # the warm start still stands.
        if not scored:
            raise
        return trials[scored[0][2]]
    if not fresh.stable:
        return trials[scored[0][2]] if scored else fresh
    return fresh if not scored or compare(fresh, sweeps).rms < scored[0][0] else trials[scored[0][2]]


def _unmasked_delay(model: Model, noise, sweeps, options, transient_s) -> Model:
    """The model, or its core identified anew behind a shorter delay (``_shorter_delays``) when that
    validates better and the model is still above ``WARM_ENOUGH`` of the floor.

    A structure that takes an error source out of the data (a hum's lines) unmasks the delay: a
    delay read long before it was chosen by validation errors that the source dominated (random
    helmet 100 FF with a hum and clipping, total delay 43: at 45, 44, 43 and 42 behind the
    clipping's exclusion 4.710x, 4.709x, 4.709x, 4.710x of the floor, so 46 stood by 0.04 %; with
    the hum's lines modelled, 1.43x at 46 against 1.06x at 43). Re-identification inside the step
    reads only delays beyond the model's (the data are shifted by it), never a shorter one.
    """
    after = compare(model, sweeps)
    if after.ratio <= WARM_ENOUGH:
        return model
    return _shorter_delays(model, after, noise, sweeps, options, transient_s)[0]


def _shorter_delays(model: Model, after, noise, sweeps, options, transient_s):
    """(model, its comparison): the core identified anew on the corrected data behind delays 1 to
    ``SHORTER_BY`` samples shorter (the latency not read again), the one of lowest validation rms if
    below the model's: ``sysid.estimation.delay.shorter_delays`` with this re-identification."""
    options = IdentificationOptions(**{**(options or REFIT_OPTIONS).__dict__, "transient_s": transient_s,
                                       "latency": False})

    def identified_behind(delay):
        recordings = _transformed(model, [noise, *sweeps], lambda u, d=delay: _shift(model.apply_input_nonlinearity(u), d),
                                  model.disturbance_frequencies)
        try:
            core = identify(recordings[0], recordings[1:], model.path, options).model
        except IdentificationError:
            return None
        trial = _with(model, _core(core), uncertainty=core.uncertainty, delay=delay,
                      identification=dict(core.identification))
        if not trial.stable:
            return None
        return trial, compare(trial, sweeps)

    return shorter_delays(model, after, identified_behind, WARM_ENOUGH)
