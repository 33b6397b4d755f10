"""The input nonlinearity's pre-filter (``input_nonlinearity_form["prefilter"]``, a Wiener-Hammerstein model):
simulated in front of the static map, in the small-signal response, saved, loaded, checked."""

import json
from dataclasses import replace

import numpy as np
import pytest
import scipy.signal

from sysid.core.errors import ModelError
from sysid.core.model import Model
from sysid.core.plants import appendix_a_model
from sysid.core.structures import highpass_factor
from sysid.simulate import simulate_session

PREFILTER = {"kind": "highpass", "order": 1, "corner_hz": 20.0}


def wiener_hammerstein(form=None) -> Model:
    return replace(appendix_a_model("fb"), input_nonlinearity=[1.0, 0.5],
                   input_nonlinearity_form={**(form or {"kind": "identity"}), "prefilter": dict(PREFILTER)})


def test_the_prefilter_acts_before_the_static_map():
    model = wiener_hammerstein()
    u = np.random.default_rng(1).standard_normal(2000) * 0.1
    w = scipy.signal.lfilter(*highpass_factor(20.0, model.fs, 1), u)
    assert np.allclose(model.apply_input_nonlinearity(u), w + 0.5 * w**2)
    # The static map alone leaves the pre-filter out: its harmonic levels are those of the pass band.
    assert np.allclose(model.static_input_nonlinearity(u), u + 0.5 * u**2)


def test_a_tanh_form_takes_a_prefilter_too():
    form = {"kind": "tanh", "scale": 0.3, "gain": 1.0, "offset": 0.0}
    model = wiener_hammerstein(form)
    u = np.linspace(-0.5, 0.5, 300)
    w = 0.3 * np.tanh(scipy.signal.lfilter(*highpass_factor(20.0, model.fs, 1), u) / 0.3)
    assert np.allclose(model.apply_input_nonlinearity(u), w + 0.5 * w**2)


def test_the_small_signal_response_carries_the_prefilter():
    model = wiener_hammerstein()
    plain = replace(model, input_nonlinearity_form=None)
    f = np.array([5.0, 20.0, 200.0])
    ratio = model.frequency_response(f) / plain.frequency_response(f)
    # A first-order high-pass at 20 Hz: -3 dB at its corner, nearly flat a decade above.
    assert abs(ratio[1]) == pytest.approx(2**-0.5, rel=0.02)
    assert abs(ratio[0]) < 0.3 and abs(ratio[2]) == pytest.approx(1.0, abs=0.01)


def test_saved_and_loaded_alike_and_old_files_unchanged(tmp_path):
    model = wiener_hammerstein()
    model.save(tmp_path / "m.json")
    loaded = Model.load(tmp_path / "m.json")
    assert loaded.input_nonlinearity_form == {"kind": "identity", "prefilter": PREFILTER}
    u = np.random.default_rng(2).standard_normal(500) * 0.05
    assert np.allclose(loaded.simulate(u), model.simulate(u))
    data = appendix_a_model("fb").to_dict()
    assert "input_nonlinearity_form" not in json.loads(json.dumps(data))


@pytest.mark.parametrize("prefilter", [{"kind": "bandpass", "order": 1, "corner_hz": 20.0},
                                       {"kind": "highpass", "order": 3, "corner_hz": 20.0},
                                       {"kind": "highpass", "order": 1, "corner_hz": 30000.0},
                                       {"kind": "highpass", "order": 1, "corner_hz": "low"},
                                       {"kind": "highpass", "order": 1}, "highpass"])
def test_a_bad_prefilter_is_refused_in_one_line(prefilter):
    data = appendix_a_model("fb").to_dict()
    data["input_nonlinearity_form"] = {"kind": "identity", "prefilter": prefilter}
    with pytest.raises(ModelError, match="prefilter") as error:
        Model.from_dict(data)
    assert "\n" not in str(error.value)


def test_a_session_with_a_coupling_highpass_before_the_driver():
    session = simulate_session(effects=["input-nonlinearity:h2_db=-25,h3_db=-120,prefilter_hz=2,prefilter_order=2"])
    plant = Model.from_dict(session.truth["plant"])
    assert plant.input_nonlinearity_form["prefilter"] == {"kind": "highpass", "order": 2, "corner_hz": 2.0}
    assert session.truth["effects"][0]["prefilter"] == plant.input_nonlinearity_form["prefilter"]
