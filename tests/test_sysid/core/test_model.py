"""The model object and its helmet-anc/model@1 JSON file."""

import json

import numpy as np
import pytest
import scipy.io

from sysid.core.errors import ModelError
from sysid.core.model import Model
from sysid.core.plants import appendix_a_model


def test_appendix_a_plants_are_stable_with_the_seeds_orders():
    fb, ff = appendix_a_model("fb"), appendix_a_model("ff")
    assert (fb.order, ff.order) == (7, 5)
    assert fb.stable and ff.stable
    # FB has non-minimum-phase zeros (seed section 4.1).
    assert np.any(np.abs(fb.zeros()) > 1.0)


def test_json_round_trip_is_exact(tmp_path):
    model = appendix_a_model("fb")
    model.delay = 3
    model.input_nonlinearity = [1.0, 0.05]
    model.history.append({"effect": "delay", "params": {"samples": 3}, "rms_before": 1e-3, "rms_after": 1e-4})
    model.save(tmp_path / "m.json")
    data = json.loads((tmp_path / "m.json").read_text())
    assert data["format"] == "helmet-anc/model@1"
    assert set(data) == {"format", "path", "fs", "A", "B", "C", "D", "delay", "input_nonlinearity", "disturbance",
                         "stable", "history", "identification"}
    assert data["input_nonlinearity"] == {"coefficients": [1.0, 0.05]} and data["disturbance"] is None
    loaded = Model.load(tmp_path / "m.json")
    for name in "ABCD":
        np.testing.assert_array_equal(getattr(loaded, name), getattr(model, name))
    assert loaded.delay == 3 and loaded.history == model.history and loaded.input_nonlinearity == [1.0, 0.05]


@pytest.mark.parametrize("key", ["format", "path", "fs", "A", "B", "C", "D"])
def test_missing_key_is_named(key):
    data = appendix_a_model("ff").to_dict()
    del data[key]
    with pytest.raises(ModelError, match=f"missing key\\(s\\): {key}"):
        Model.from_dict(data)


def test_bad_dimensions_and_values_are_named(tmp_path):
    data = appendix_a_model("ff").to_dict()
    data["B"] = [[1.0], [2.0]]
    with pytest.raises(ModelError, match=r"Incompatible dimensions of B matrix; expected \(5, 1\) but found \(2, 1\)"):
        Model.from_dict(data)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ModelError, match=r"bad.json: not valid JSON"):
        Model.load(tmp_path / "bad.json")
    with pytest.raises(ModelError, match="path must be one of fb, ff"):
        Model(path="xx", fs=44100, A=[[0.5]], B=[[1]], C=[[1]], D=[[0]])


def test_simulate_applies_nonlinearity_then_delay():
    model = Model(path="fb", fs=44100.0, A=[[0.5]], B=[[1.0]], C=[[1.0]], D=[[0.0]], delay=2,
                  input_nonlinearity=[2.0, 1.0])
    u = np.zeros(8)
    u[0] = 1.0
    # v = 2u + u^2 = 3 at t=0; delayed by 2 then y(t) = 0.5^(t-1) v(t-1).
    np.testing.assert_allclose(model.simulate(u), [0, 0, 0, 3.0, 1.5, 0.75, 0.375, 0.1875])


def test_statespace_export_matches_the_frequency_response():
    control = pytest.importorskip("control")
    model = appendix_a_model("ff")
    model.delay = 4
    sys = model.to_statespace()
    f = np.array([50.0, 500.0, 3000.0])
    expected = model.frequency_response(f)
    got = np.array([complex(sys(np.exp(2j * np.pi * fk / model.fs))) for fk in f])
    np.testing.assert_allclose(got, expected, rtol=1e-8)
    assert isinstance(sys, control.StateSpace) and sys.dt == pytest.approx(1 / 44100)


def test_mat_export(tmp_path):
    model = appendix_a_model("fb")
    model.save_mat(tmp_path / "m.mat")
    data = scipy.io.loadmat(tmp_path / "m.mat")
    np.testing.assert_array_equal(data["A"], model.A)
    assert data["Ts"][0, 0] == pytest.approx(1 / 44100)


def test_saved_files_get_the_ordinary_file_mode(tmp_path):
    import os

    umask = os.umask(0o022)
    try:
        appendix_a_model("ff").save(tmp_path / "m.json")
    finally:
        os.umask(umask)
    assert (tmp_path / "m.json").stat().st_mode & 0o777 == 0o644
