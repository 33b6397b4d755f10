"""More states from the long estimate: the refit that adds a reverberant tail (``sysid.findings.tail``).

The model's core is replaced by a longer one read off the data without iterating: the
least-squares FIR of the model's corrected data (the recordings as its core sees them:
``sysid.refits.machinery._transformed``, input polynomial and delay applied, disturbance and
offset out), its frequency-limited balanced truncation (``sysid.estimation.long_response``)
at the lowest order that reaches the floor, and no more than the ``states`` asked (the
detector's estimate, held to the state cap by ``refine``): the detector's own ladder
(``sysid.findings.tail.truncation_ladder``) on the corrected data. Where affordable (at most
``TAIL_OE_MAX_ORDER`` states) the truncation is refined by output error on the raw DFT data
(``sysid.estimation.output_error``), which beats truncation at equal order; the better on
the sweeps is kept, and ``refine`` keeps the step only if it validates better. A model that holds a delay
is tried behind it and from the input on (its delay then 0, the onset in the states): a capped model may
have fitted a delay into a measured response's slow onset, which the longer core holds.

The refined model is a plain state-space model of the higher order, not a parallel FIR
tail beside the core: the model contract (design.md, "The model") is unchanged, and every
consumer (``compare``, the report, controller design, the generated C: a realisation in
second-order sections) works on it as it is. A parallel FIR would need a new model field,
a new simulation path in every consumer and a new C kernel, for a response that
hundreds of well-damped states reproduce at the floor (HD 600 on a KEMAR: about 330).
"""

from __future__ import annotations

from ..core import lti
from ..core.errors import IdentificationError
from ..core.model import Model
from ..core.thresholds import IDENTIFICATION_BAND, TAIL_OE_MAX_ORDER
from ..estimation.output_error import block_data, refine_output_error
from ..findings.tail import long_response, tail_finding, truncation_ladder
from ..validation.compare import compare
from ..validation.sweeps import sweep_spectrum
from .machinery import REFIT_OPTIONS, _shift, _transformed, _with

__all__ = ["add_tail", "complete_states"]


def complete_states(params: dict, ctx, before) -> dict:
    """``refine --add reverberant-tail`` without ``states``: the detector's estimate of what the data need."""
    if params.get("states") is None:
        params["states"] = int(tail_finding(ctx)["params"].get("states", ctx.model.order))
    if params["states"] <= ctx.model.order:
        raise IdentificationError(f"--add reverberant-tail: the model holds {ctx.model.order} states already; "
                                  f"give more (reverberant-tail:states=N)")
    return params


def add_tail(model: Model, noise, sweeps, params, options, transient_s):
    """The core from the long estimate's truncation at the states the data need (at most ``params["states"]``)."""
    states = int(params["states"])
    if states <= model.order:
        raise IdentificationError(f"reverberant-tail: {states} states are no more than the model's {model.order}")
    floor = compare(model, sweeps).noise_floor
    # Behind the model's delay, and from the input on when it holds one: a delay fitted by a capped model may cut
    # into a slow onset that the longer core holds (the detector judges both the same way).
    trials = []
    for delay in dict.fromkeys((model.delay, 0)):
        trials += _trials(model, noise, sweeps, states, delay, floor, options, transient_s)
    scored = sorted(((compare(t, sweeps).rms, k) for k, (t, _) in enumerate(trials) if t.stable))
    if not scored:
        raise IdentificationError(f"reverberant-tail: no truncation of at most {states} states is stable")
    best, extra = trials[scored[0][1]]
    return best, {"order": best.order, **extra}


def _trials(model: Model, noise, sweeps, states: int, delay: int, floor: float, options, transient_s) -> list:
    """[(model, what it is), ...]: the long estimate behind ``delay`` samples truncated at the lowest order up to
    ``states`` that reaches the floor, and its output-error refinement where affordable."""
    plain = model.apply_input_nonlinearity
    recordings = _transformed(model, [noise, *sweeps], lambda u: _shift(plain(u), delay), model.disturbance_frequencies)
    # The corrected recordings are what a bare core sees: no delay, polynomial, offset or lines of its own.
    bare = Model(path=model.path, fs=model.fs, A=model.A, B=model.B, C=model.C, D=model.D)
    response = long_response(bare, recordings[0], transient_s)
    spectra = [sweep_spectrum(r) for r in recordings[1:]]
    # From the states asked down to the lowest that reaches the floor (the detector's ladder ran upwards).
    ladder = truncation_ladder(response.taps, model.fs, 0, spectra, floor, start=states, cap=states,
                               lowest=model.order + 1)
    order = ladder.needed if ladder.needed is not None else ladder.best
    system, reflected = ladder.truncation.realisation(order)
    truncated = _with(model, lti.balanced_realisation(*system), delay=delay)
    what = {"fir_taps": int(response.taps.size), "length_ms": 1e3 * response.length_s,
            "truncation_ratio": ladder.ratio(order), "reflected_poles": reflected, "output_error": False}
    trials = [(truncated, what)]
    if order <= TAIL_OE_MAX_ORDER and truncated.stable:
        seconds = (options or REFIT_OPTIONS).refine_seconds
        data = block_data(recordings[0].trimmed(transient_s), IDENTIFICATION_BAND, seconds)
        try:
            oe = refine_output_error(truncated.A, truncated.B, truncated.C, truncated.D, data,
                                     feedthrough=bool(truncated.D[0, 0]), noise_tolerance=True)
            trials.append((_with(model, (oe.A, oe.B, oe.C, oe.D), delay=delay), {**what, "output_error": True}))
        except IdentificationError:
            pass
    return trials
