"""add_input_nonlinearity: the shape that validates better, fitted with the core, which keeps its order."""

import pytest
from conftest import FAST_OPTIONS
from effect_units import true_session

from sysid.core.model import Model
from sysid.refine import refine


@pytest.mark.parametrize("effect, shape", [("input-nonlinearity:h3_db=-22,h2_db=-120,tanh=1", "tanh"),
                                           ("input-nonlinearity:h2_db=-22,h3_db=-120", "polynomial")])
def test_the_shape_of_the_data_is_chosen_and_the_core_keeps_its_order(effect, shape):
    session = true_session("ff", 3, (effect,))
    base = Model.from_dict(session.truth["base_plant"])
    step = refine(base, session.noise, session.sweeps, "input-nonlinearity", FAST_OPTIONS)
    model = step.model
    assert step.after.ratio < 1.2
    assert model.order == base.order
    assert (model.input_nonlinearity_form is not None) == (shape == "tanh")
    assert (model.input_nonlinearity is not None) == (shape == "polynomial")
    assert model.identification["drive_limit_fs"] > 0
