"""Sessions users reported that crashed identification: a plausible 48 kHz helmet path, and ``refine --auto`` on a
feed-forward session with a delay, hum and a saturating input. The refinement's start label carried its gamma as
text ("grid gamma=820, walked" once the delay was walked) and was parsed back; the gamma is data now."""

import dataclasses
import importlib
import json

import numpy as np

import pytest
from conftest import FAST_OPTIONS

from helmet_anc.cli import main
from sysid.core.model import Model
from sysid.identify import identify
from sysid.random_plant import _continuous_statespace, _zoh_modal
from sysid.simulate import SessionSpec, simulate_session

# The order search's route (sysid.estimation.route): where the gamma and the walked delay's labels are made.
SEARCH = dataclasses.replace(FAST_OPTIONS, route="search")

# Three modes (Hz, Q, signed peak gain) behind a 4.1 kHz roll-off and 9 samples of delay, at 48 kHz.
HELMET_48K = [(1254.0, 5.9, 0.48), (2027.0, 2.6, 0.45), (2483.0, 14.8, -0.49)]


def helmet_48k() -> Model:
    A, B, C, D = _zoh_modal(*_continuous_statespace(HELMET_48K, (4100.0,), None), 48000.0)
    return Model(path="fb", fs=48000.0, A=A, B=B, C=C, D=D, delay=9)


def test_the_48_khz_helmet_is_identified_at_the_floor_with_its_gamma_as_data():
    spec = SessionSpec(path="fb", seed=5, fs=48000.0, output_noise=1.4e-4, noise_duration=8.0, sweep_duration=2.0,
                       sweep_silence=0.2)
    session = simulate_session(spec, plant=helmet_48k())
    result = identify(session.noise, session.sweeps, "fb", SEARCH)
    info = result.model.identification
    assert info["rms"] < 1.1 * result.noise_floor
    assert abs(result.model.delay - 9) <= 2
    assert isinstance(info["gamma"], int) and info["gamma"] in FAST_OPTIONS.gammas
    assert isinstance(info["refinement"]["start_gamma"], int)
    json.loads(result.model.to_json())


@pytest.mark.slow
def test_refine_auto_on_a_session_with_delay_hum_and_a_saturating_input(tmp_path, capsys):
    """Before the gamma was data: ValueError: invalid literal for int() with base 10: '820, walked' (2 min)."""
    clean, late = tmp_path / "clean", tmp_path / "late"
    assert main(["-q", "simulate", str(clean), "--path", "ff", "--seed", "1", "--noise-seconds", "8",
                 "--sweep-seconds", "2"]) == 0
    recordings = lambda folder: ["--noise", str(folder / "noise.wav"), "--sweep", str(folder / "sweep1.wav"),  # noqa: E731
                                 "--sweep", str(folder / "sweep2.wav")]
    assert main(["-q", "identify", *recordings(clean), "--path", "ff", "-o", str(tmp_path / "m.json")]) == 0
    assert main(["-q", "simulate", str(late), "--path", "ff", "--seed", "2", "--noise-seconds", "8", "--sweep-seconds",
                 "2", "--effect", "delay:23", "--effect", "periodic-disturbance", "--effect",
                 "input-nonlinearity"]) == 0
    capsys.readouterr()
    code = main(["-q", "refine", str(tmp_path / "m.json"), "--auto", *recordings(late), "-o", str(tmp_path / "r.json")])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "Traceback" not in err and "stopped:" in out
    model = Model.load(tmp_path / "r.json")
    gamma = model.identification.get("gamma")
    assert gamma is None or isinstance(gamma, int)


def test_a_model_kept_from_the_seed_grid_records_its_own_gamma(sessions, monkeypatch):
    """When the refinement validates worse, the seed grid's model is returned: its gamma is the grid's choice,
    not the gamma the rejected refinement started from (which its provenance keeps under ``refinement``)."""
    pipeline = importlib.import_module("sysid.identify")  # the module, not the facade's function of that name
    session = sessions["ff"]

    def worse(data, spectra, grid, floor, provenance, progress, lead=0):
        model = Model(path=data.path, fs=data.body.fs, A=[[0.5]], B=[[1.0]], C=[[1.0]], D=[[0.0]],
                      identification=dict(provenance, refinement={"start_gamma": 7, "start": "raw subspace",
                                                                  "order": 1}))
        return model, np.inf, [], None

    monkeypatch.setattr(pipeline, "_refine", worse)
    result = identify(session.noise, session.sweeps, "ff", SEARCH)
    info = result.model.identification
    assert result.model is result.seed_model and not info["refined"]
    assert info["gamma"] == result.grid.chosen.gamma == info["seed_choice"]["gamma"]
    assert info["refinement"]["start_gamma"] == 7 and "rejected" in info["refinement"]


@pytest.mark.parametrize("label", ["grid gamma=820, walked", "grid gamma=820, walked, freed pole dropped",
                                   "order 7 + real pole, walked"])
def test_the_labels_a_walked_delay_produces_are_never_read_for_the_gamma(label, sessions, monkeypatch):
    """A pick moved behind a walked delay carries labels like these (sysid.estimation.delay.trials); the gamma
    it records is the candidate's own, 820 here, never a number parsed out of the label."""
    import dataclasses

    pipeline = importlib.import_module("sysid.identify")
    settle = pipeline._settle

    def walked(pick, pick_rms, block, data):
        pick, pick_rms = settle(pick, pick_rms, block, data)
        return dataclasses.replace(pick, start=label, gamma=820), pick_rms

    monkeypatch.setattr(pipeline, "_settle", walked)
    session = sessions["ff"]
    result = identify(session.noise, session.sweeps, "ff", SEARCH)
    info = result.model.identification
    assert info["refinement"]["start"] == label and info["refinement"]["start_gamma"] == 820
    assert info["gamma"] == (820 if info["refined"] else result.grid.chosen.gamma)
