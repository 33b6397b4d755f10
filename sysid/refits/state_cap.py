"""The state cap refinement holds a model to: what the board can afford (``max_order``, ``--max-order N``).

A cap given to ``refine`` or ``refine_auto`` (``sysid.refine``), or else the one the model was identified
under (``identification["max_order"]``), bounds every step that adds states: ``states`` (the order after
the step, the reverberant tail's) or ``extra_order`` (states added, under-modelled's) are cut to it, and
``refine_auto`` stops at it saying how far from the floor the model is and what more states would buy
(the reverberant tail's truncation ladder, ``sysid.findings.tail``).
"""

from __future__ import annotations

import numpy as np

from ..core.effect_spec import EffectSpec
from ..core.errors import IdentificationError
from ..core.model import Model
from ..findings.tail import ladder_text
from ..validation.compare import Comparison

__all__ = ["state_cap", "held_to_cap", "within_cap", "more_states", "at_cap"]


def state_cap(model: Model, max_order: int | None = None) -> int | None:
    """The state cap refinement holds to: ``max_order`` if given, else the model's own
    (``identification["max_order"]``, the cap it was identified under), else None (no cap)."""
    cap = max_order if max_order is not None else model.identification.get("max_order")
    if cap is None:
        return None
    if isinstance(cap, bool) or not isinstance(cap, (int, np.integer)) or cap < 1:
        raise IdentificationError(f"--max-order must be a whole number of states of at least 1; found {cap!r}")
    return int(cap)


def held_to_cap(kind: str, params: dict, model: Model, cap: int | None) -> dict:
    """``params`` with the states they add cut to ``cap``: ``states`` (the order after the step) or
    ``extra_order`` (states added); IdentificationError when the model is at the cap already."""
    if cap is None or not ({"states", "extra_order"} & set(params)):
        return params
    room = cap - model.order
    if room <= 0:
        raise IdentificationError(f"--add {kind}: the model holds {model.order} states, at the state cap of {cap} "
                                  f"(--max-order)")
    params = dict(params)
    if params.get("states") is not None:
        params["states"] = min(int(params["states"]), cap)
    if params.get("extra_order") is not None:
        params["extra_order"] = min(int(params["extra_order"]), room)
    return params


def more_states(diagnosis, model: Model) -> list[dict]:
    """The findings that add states, in the order ``refine_auto`` falls back on them: the reverberant tail's
    when its truncation ladder reaches the floor above the model's order, then under-modelled's one mode."""
    tail = [f for f in diagnosis if f["effect"] == "reverberant-tail" and f["params"].get("states_reach_floor")
            and f["params"].get("states", 0) > model.order]
    return tail[:1] + [{"effect": "under-modelled", "params": {}, "score": 0.0}]


def within_cap(specs: list, model: Model, cap: int | None) -> tuple[list, bool]:
    """(the steps with the states they add cut to the state cap, whether a step was cut or left out at it)."""
    kept, capped = [], False
    for f, spec in specs:
        try:
            held = held_to_cap(spec.kind, spec.params, model, cap)
        except IdentificationError:
            capped = True
            continue
        capped = capped or held != spec.params
        kept.append((f, EffectSpec(spec.kind, held)))
    return kept, capped


def at_cap(cap: int, model: Model, current: Comparison, diagnosis) -> str:
    """Why ``refine_auto`` stopped at the state cap: how far from the floor, and what more states would buy (the
    reverberant tail's truncation ladder, when diagnose read one)."""
    text = f"at the state cap ({cap} states, --max-order): the validation error is {current.ratio:.2f}x the noise floor"
    tail = next((f for f in diagnosis if f.effect == "reverberant-tail" and f.params.get("ladder")), None)
    if tail is None:
        return text + f"; more states might lower it (refine --auto --max-order {model.order + 2} or more)"
    states = tail.params["states"]
    more = ladder_text(tail.params["ladder"], model.order, states)
    if tail.params.get("states_reach_floor"):
        reach = f"the reverberant tail reaches the floor at about {states} states"
    else:
        # The ladder's plateau: the states that pay, short of the floor (what is left is not for more states).
        reach = (f"the reverberant tail's states that pay are about {states} ({tail.params['rms_at_states']:.2f}x; "
                 f"more buy little)")
    return text + f"; {reach} (the long estimate truncated: {more}): refine --auto --max-order {states}"
