"""The model's parametric input nonlinearity (``input_nonlinearity_form``): simulated, saved, loaded, checked."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from sysid.core.errors import ModelError
from sysid.core.model import Model
from sysid.core.plants import appendix_a_model

FORM = {"kind": "tanh", "scale": 0.3, "gain": 1.2, "offset": 0.05}


def test_the_form_is_the_saturation_of_the_docstring():
    model = appendix_a_model("fb")
    model.input_nonlinearity_form = dict(FORM)
    u = np.linspace(-1, 1, 101)
    expected = 1.2 * 0.3 * (np.tanh((u + 0.05) / 0.3) - math.tanh(0.05 / 0.3))
    assert np.allclose(model.apply_input_nonlinearity(u), expected)
    assert model.apply_input_nonlinearity(np.zeros(3)) == pytest.approx(0.0)


def test_a_polynomial_follows_the_form():
    model = Model(path="fb", fs=44100.0, A=[[0.5]], B=[[1.0]], C=[[1.0]], D=[[0.0]],
                  input_nonlinearity=[1.0, 0.5], input_nonlinearity_form={"kind": "tanh", "scale": 2.0})
    u = np.array([-0.4, 0.1, 0.7])
    w = 2.0 * np.tanh(u / 2.0)
    assert np.allclose(model.apply_input_nonlinearity(u), w + 0.5 * w**2)


def test_the_small_signal_gain_is_in_the_frequency_response():
    model = appendix_a_model("ff")
    plain = model.frequency_response([100.0, 1000.0])
    model.input_nonlinearity_form = dict(FORM)
    slope = 1.2 / math.cosh(0.05 / 0.3) ** 2
    assert np.allclose(model.frequency_response([100.0, 1000.0]), slope * plain)


def test_round_trip_and_defaults(tmp_path):
    model = replace(appendix_a_model("fb"), input_nonlinearity_form={"kind": "tanh", "scale": 0.25})
    model.save(tmp_path / "m.json")
    loaded = Model.load(tmp_path / "m.json")
    assert loaded.input_nonlinearity_form == {"kind": "tanh", "scale": 0.25, "gain": 1.0, "offset": 0.0}
    u = np.random.default_rng(0).standard_normal(500) * 0.3
    assert np.array_equal(loaded.simulate(u), model.simulate(u))


def test_a_model_without_the_form_writes_what_it_wrote_before():
    model = appendix_a_model("fb")
    data = json.loads(model.to_json())
    assert "input_nonlinearity_form" not in data
    assert Model.from_dict(data).input_nonlinearity_form is None


@pytest.mark.parametrize("form, message", [
    ({"kind": "cubic", "scale": 1.0}, "kind"),
    ({"kind": "tanh"}, "scale must be a positive"),
    ({"kind": "tanh", "scale": -1.0}, "scale must be a positive"),
    ({"kind": "tanh", "scale": 1.0, "gain": "x"}, "must be numbers"),
    ({"kind": "tanh", "scale": 1.0, "offset": 50.0}, "offset within"),
    ("tanh", "must be null or an object"),
])
def test_bad_forms_are_refused(form, message):
    data = appendix_a_model("fb").to_dict()
    data["input_nonlinearity_form"] = form
    with pytest.raises(ModelError, match=message):
        Model.from_dict(data)
