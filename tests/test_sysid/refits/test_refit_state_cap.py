"""The state cap refinement holds a model to: its default, the steps cut to it, and what refine --auto says there."""

from types import SimpleNamespace

import numpy as np
import pytest

from sysid.core.effect_spec import EffectSpec
from sysid.core.errors import IdentificationError
from sysid.core.model import Model
from sysid.refits.state_cap import at_cap, held_to_cap, more_states, state_cap, within_cap


def model_of(order: int, **identification) -> Model:
    A = 0.5 * np.eye(order)
    return Model(path="fb", fs=44100.0, A=A, B=np.ones((order, 1)), C=np.ones((1, order)), D=[[0.0]],
                 identification=identification)


def test_the_cap_given_wins_over_the_model_s_own_and_none_is_no_cap():
    assert state_cap(model_of(4, max_order=30)) == 30
    assert state_cap(model_of(4, max_order=30), 12) == 12
    assert state_cap(model_of(4)) is None


@pytest.mark.parametrize("cap", [0, -3, 2.5, True, "12"])
def test_a_cap_that_is_no_number_of_states_is_an_error(cap):
    with pytest.raises(IdentificationError, match="--max-order"):
        state_cap(model_of(4), cap)


def test_steps_that_add_states_are_cut_to_the_cap():
    model = model_of(10)
    assert held_to_cap("reverberant-tail", {"states": 300}, model, 40) == {"states": 40}
    assert held_to_cap("under-modelled", {"extra_order": 6}, model, 12) == {"extra_order": 2}
    assert held_to_cap("delay", {"samples": 3}, model, 10) == {"samples": 3}  # adds no states
    assert held_to_cap("reverberant-tail", {"states": 300}, model, None) == {"states": 300}
    with pytest.raises(IdentificationError, match="state cap of 10"):
        held_to_cap("under-modelled", {"extra_order": 2}, model, 10)


def test_refine_auto_s_candidates_at_the_cap_are_cut_or_left_out():
    model = model_of(10)
    found = {"effect": "reverberant-tail"}
    kept, capped = within_cap([(found, EffectSpec("reverberant-tail", {"states": 300}))], model, 20)
    assert capped and kept[0][1].params == {"states": 20}
    kept, capped = within_cap([(found, EffectSpec("under-modelled", {"extra_order": 2}))], model, 10)
    assert capped and kept == []
    kept, capped = within_cap([(found, EffectSpec("delay", {"samples": 3}))], model, 10)
    assert not capped and len(kept) == 1


class _Finding(dict):
    """A finding as diagnose gives it: readable by key and by attribute."""

    def __init__(self, effect, params):
        super().__init__(effect=effect, params=params)
        self.effect, self.params = effect, params


def test_more_states_falls_back_on_the_tail_s_ladder_before_one_more_mode():
    model = model_of(12)
    tail = _Finding("reverberant-tail", {"states": 23, "states_reach_floor": True})
    assert [f["effect"] for f in more_states([tail], model)] == ["reverberant-tail", "under-modelled"]
    short = _Finding("reverberant-tail", {"states": 18, "states_reach_floor": False})
    assert [f["effect"] for f in more_states([short], model)] == ["under-modelled"]


def test_at_the_cap_it_says_how_far_and_what_more_states_buy():
    model = model_of(12)
    current = SimpleNamespace(ratio=5.83)
    tail = _Finding("reverberant-tail", {"states": 23, "states_reach_floor": True, "rms_at_states": 1.13,
                                         "ladder": [[12, 10.7], [18, 6.78], [23, 1.13], [48, 1.11]]})
    text = at_cap(12, model, current, [tail])
    assert text.startswith("at the state cap (12 states, --max-order): the validation error is 5.83x")
    assert "reaches the floor at about 23 states" in text and "18 states 6.78x, 23 states 1.13x" in text
    assert text.endswith("refine --auto --max-order 23")
    assert at_cap(12, model, current, []).endswith("refine --auto --max-order 14 or more)")
