"""The long route's model of one session: its order under the user's cap, refined, reduced, and where it came from.

``long_model`` turns a ``long_route.LongEstimate`` into a ``sysid.core.model.Model``: the lowest order
at the floor its truncation ladder shows, under the cap (``IdentificationOptions.max_order``),
refined there (``long_route.refine_long``), then, up to ``LONG_OE_ORDER`` states, freed of the
states the data did not ask for as the order search's models are (``reduction.without_degenerate_states``:
poles at the block's radius bound, states no balanced realisation holds, a negligible balanced tail);
above it balanced (``lti.balanced_realisation``). Its provenance says how (``identification["long_route"]``)
and its delay is the long route's (``sysid.estimation.delay.fir``).
"""

from __future__ import annotations

from dataclasses import dataclass

from ..core import lti
from ..core.model import Model
from ..core.thresholds import DEFAULT_ORDERS, LONG_OE_ORDER, LONG_OE_SECONDS
from ..io.lines import without_lines
from ..io.recordings import Recording, RecordingFile
from ..validation.sweeps import simulated_rms
from .delay.onset import compensate_delay, delay_centimetres
from .long_route import LongEstimate, refine_long
from .output_error import block_data
from .reduction import without_degenerate_states

__all__ = ["LongRouteModel", "long_model"]

_REFINEMENTS = {"truncation": "the truncation as it is", "output error": "output-error refinement",
                "numerator": "its numerator refitted on raw DFT data"}


@dataclass
class LongRouteModel:
    """The model, its time-domain validation rms on the sweeps (FS), and the noise block behind its delay (for its
    95 % band)."""

    model: Model
    rms: float
    body: Recording


def long_model(estimate: LongEstimate, noise: Recording | RecordingFile, sweeps: list[Recording], lines: list[float],
               floor: float, provenance: dict, path: str, options) -> LongRouteModel:
    """The long route's model (module docstring). ``options``: the ``IdentificationOptions`` of the call (its cap,
    orders, bands, seconds, at_floor and min_gain); ``lines``: the frequencies (Hz) of the lines taken out of the
    sweeps, taken out of the noise recording too; ``provenance``: the identification's, which the model's extends."""
    order = at_floor = estimate.curve.lowest_at_floor(options.at_floor, options.min_gain, options.max_order)
    if tuple(options.orders) != DEFAULT_ORDERS:
        # Orders given (a refit's re-identification at the model's own order and a few above): within them.
        order = min(max(order, min(options.orders)), max(options.orders))
    # No more states than the truncation holds: the frequency-limited Gramians' numerical rank (the HD 600's FIR of
    # 1980 taps: 473); orders above it would add states the data do not determine.
    order = min(order, estimate.truncation.max_order)
    body = noise.trimmed(options.transient_s)
    body = body.advanced(estimate.line) if isinstance(body, RecordingFile) else compensate_delay(body, estimate.line)
    body = without_lines(body.head(max(options.refine_seconds, options.scan_seconds)), lines)
    block = block_data(body, options.band, LONG_OE_SECONDS)
    # Above the floor's order the numerator's refit is not tried: the floor's order is the fallback, and at the
    # HD 600's 473 states that one linear step on the block took 42 of the call's 74 s (wall, loaded machine) to
    # validate worse than the floor's 332 states, where the model went anyway.
    core = refine_long(estimate, order, block, floor, True, options.at_floor, options.min_gain, order <= at_floor)
    dropped = None
    limit = estimate.curve.rms[estimate.curve.orders.index(at_floor)] * (1 + options.min_gain)
    if core.order > at_floor and core.rms > limit:
        # More states than the floor asks for that validate worse than the floor's order (the HD 600's 23 s session
        # truncated to all 473 states its Gramians hold: 5.5x the floor, where 332 states reach 1.05x): the floor's.
        dropped = {"order": core.order, "ratio": round(float(core.rms) / floor, 4)}
        core = refine_long(estimate, at_floor, block, floor, True, options.at_floor, options.min_gain)
    system, removed = (core.A, core.B, core.C, core.D), ""

    def time_rms(c) -> float:
        trial = Model(path=path, fs=noise.fs, A=c.A, B=c.B, C=c.C, D=c.D, delay=estimate.line)
        return simulated_rms(trial, sweeps, options.validation_band)

    rms = time_rms(core)
    if core.order <= LONG_OE_ORDER:
        reduced = without_degenerate_states(*system, rms, block, time_rms, options.min_gain, estimate.feedthrough)
        system, rms, removed = (reduced.A, reduced.B, reduced.C, reduced.D), reduced.rms, reduced.removed
    else:
        system = lti.balanced_realisation(*system)
    delay = {"samples": estimate.line, "centimetres": round(delay_centimetres(estimate.line, noise.fs), 2),
             **estimate.delay.to_dict(), "samples_before_response": estimate.delay.taps}
    info = dict(provenance, route="long route", latency=delay,
                method="long route: least-squares FIR, its frequency-limited balanced truncation, then "
                       + _REFINEMENTS[core.refinement],
                long_route=dict(estimate.to_dict(), order=core.order, refinement=core.refinement,
                                most_states=estimate.truncation.max_order, dropped=dropped,
                                reflected_poles=core.reflected, block_seconds=LONG_OE_SECONDS, reduced=removed,
                                tried={str(n): round(float(r) / floor, 4) for n, r in core.tried.items()}))
    model = Model(path=path, fs=noise.fs, A=system[0], B=system[1], C=system[2], D=system[3], delay=estimate.line,
                  identification=info)
    estimate.curve.refined.update(core.tried)
    if model.order not in core.tried:
        estimate.curve.refined[model.order] = float(rms)
    return LongRouteModel(model, float(rms), body)
