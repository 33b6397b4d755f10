"""Identification of the seed's appendix-A plants from short simulated sessions."""

import numpy as np
import pytest
from conftest import FAST_OPTIONS

from sysid.core.errors import IdentificationError, RecordingError
from sysid.identify import IdentificationOptions, identify
from sysid.io.recordings import Recording
from sysid.validation.sweeps import simulated_rms

BAND = np.linspace(20.0, 1500.0, 400)


@pytest.mark.parametrize("path", ["fb", "ff"])
class TestAppendixAPlants:
    def test_model_is_stable(self, identifications, path):
        model = identifications[path].model
        assert model.stable
        assert model.identification["rms"] > 0

    def test_frequency_response_within_1_db_and_10_degrees(self, identifications, sessions, path):
        model, plant = identifications[path].model, sessions[path].plant
        ratio = model.frequency_response(BAND) / plant.frequency_response(BAND)
        assert np.max(np.abs(20 * np.log10(np.abs(ratio)))) < 1.0
        assert np.max(np.abs(np.angle(ratio, deg=True))) < 10.0

    def test_validation_rms_within_10_percent_of_true_plant(self, identifications, sessions, path):
        session = sessions[path]
        true_rms = simulated_rms(session.plant, session.sweeps)
        assert identifications[path].model.identification["rms"] <= 1.10 * true_rms

    def test_refinement_beats_seed_grid_and_is_reported(self, identifications, path):
        result = identifications[path]
        assert result.refined_rms is not None and result.refined_rms < result.seed_rms
        info = result.model.identification
        assert info["seed_choice"]["rms"] == pytest.approx(result.seed_rms)
        assert info["refined"] is True


def test_grid_keeps_only_stable_candidates(identifications):
    grid = identifications["fb"].grid
    assert grid.rms.shape == (len(FAST_OPTIONS.gammas), 20)
    assert grid.chosen.fit.stable
    assert np.nanmin(grid.rms) == pytest.approx(min(c.rms for c in grid.best), rel=0.05)


def test_seed_average_estimator_gives_a_stable_model(sessions):
    session = sessions["ff"]
    options = IdentificationOptions(estimator="seed-average", gammas=(90, 500), orders=(3, 4, 5, 6), refine=False)
    result = identify(session.noise, session.sweeps, "ff", options)
    assert result.model.stable
    assert result.model.identification["estimator"] == "seed-average"
    assert result.refined_rms is None


def test_unknown_estimator_is_rejected(sessions):
    session = sessions["ff"]
    with pytest.raises(IdentificationError, match="estimator must be one of"):
        identify(session.noise, session.sweeps, "ff", IdentificationOptions(estimator="h3"))


def test_noise_recording_shorter_than_one_segment_is_rejected(sessions):
    session = sessions["ff"]
    short = Recording(session.noise.u[: int(3.02 * 44100)], session.noise.y[: int(3.02 * 44100)], 44100.0, "short.wav")
    with pytest.raises(RecordingError, match="short.wav: a noise recording of 3.02 s is too short"):
        identify(short, session.sweeps, "ff", FAST_OPTIONS)


def test_sample_rate_mismatch_is_rejected(sessions):
    session = sessions["ff"]
    other = Recording(session.sweeps[1].u, session.sweeps[1].y, 48000.0, "sweep48k.wav")
    with pytest.raises(RecordingError, match="sweep48k.wav: sample rate 48000 Hz differs"):
        identify(session.noise, [session.sweeps[0], other], "ff", FAST_OPTIONS)


def test_gamma_beyond_half_segment_is_rejected(sessions):
    session = sessions["ff"]
    with pytest.raises(IdentificationError, match="exceeds half the segment length"):
        identify(session.noise, session.sweeps, "ff", IdentificationOptions(gammas=(2000,)))


def test_a_delay_decided_one_sample_long_is_tried_one_shorter(monkeypatch):
    # Random helmet 94 (short session; a 1.2 kHz mode of Q 0.85, a 75 Hz high-pass, pure delay 19): the onset
    # reads 23, and the costs at the picked core barely tell 19 from 20, so the decision may land on 20 by
    # round-off, where no causal core reaches the floor. Forced there, identify moves the core behind both 20
    # and 19 (the shorter kept when it validates better by more than min_gain), and never past the decision.
    import sys

    from sysid.estimation.delay import DelayWalk, decide_delay
    from sysid.random_plant import random_plant, random_session

    trials = sys.modules["sysid.estimation.delay.trials"]
    plant = random_plant(94)
    session = random_session(94, noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)
    decided, moves = [], []

    def one_sample_long(A, noise, band, seconds, delay=0, **kwargs):
        walk = decide_delay(A, noise, band, seconds, delay, **kwargs)
        decided.append(delay)
        return DelayWalk(plant.delay + 1 - delay, walk.A, walk.costs, walk.fits)

    def recorded(recording, samples):
        moves.append(samples)
        return compensate_delay(recording, samples)

    compensate_delay = trials.compensate_delay
    monkeypatch.setattr(trials, "decide_delay", one_sample_long)
    monkeypatch.setattr(trials, "compensate_delay", recorded)
    model = identify(session.noise, session.sweeps, "fb", IdentificationOptions(gammas=tuple(range(10, 1001, 30)))).model
    onset = decided[0]
    assert onset > plant.delay + 1  # read long
    tried = {onset + m for m in moves if m < 0}
    assert {plant.delay + 1, plant.delay} <= tried
    assert model.delay in (plant.delay, plant.delay + 1)


def test_the_start_gamma_is_the_grid_gamma_the_pick_descends_from(identifications):
    # The refinement's start_gamma is data on the pick (``OrderCandidate.gamma``), not read back from its label:
    # a pick from a ``grid gamma=G`` start says G, whatever was done to it since.
    for result in identifications.values():
        refinement = result.model.identification.get("refinement", {})
        if refinement.get("start", "").startswith("grid gamma="):
            assert refinement["start_gamma"] == int(refinement["start"].split("=")[1].split(",")[0])


# Random helmet 94 FF (short session): one 4.7 kHz mode behind 16 samples, at the floor from 2 to 6 states; its order
# was a near-tie that OpenBLAS's kernel decided (3 states with the Haswell kernel, 2 with Sandybridge's).
_IDENTIFIED_IN_A_PROCESS = """
import json
import numpy as np
from threadpoolctl import threadpool_info
from sysid.identify import IdentificationOptions, identify
from sysid.random_plant import random_session
session = random_session(94, "ff", noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)
model = identify(session.noise, session.sweeps, "ff", IdentificationOptions(gammas=tuple(range(10, 1001, 30)))).model
h = model.frequency_response(np.geomspace(20.0, 20000.0, 400))
print(json.dumps({"kernels": sorted({i.get("architecture", "") for i in threadpool_info() if i["user_api"] == "blas"}),
                  "order": model.order, "delay": model.delay, "re": h.real.tolist(), "im": h.imag.tolist()}))
"""


def _identified_with_kernel(coretype: str) -> dict:
    """What ``_IDENTIFIED_IN_A_PROCESS`` prints in a fresh interpreter with OpenBLAS's kernel forced to ``coretype``."""
    import json
    import os
    import subprocess
    import sys

    from repo import REPO

    env = dict(os.environ, OPENBLAS_CORETYPE=coretype,
               PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    done = subprocess.run([sys.executable, "-c", _IDENTIFIED_IN_A_PROCESS], capture_output=True, text=True, env=env,
                          timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_the_same_session_gives_the_same_model_whatever_blas_kernel_runs_it():
    # Kernels differing in the last bits of every factorisation: the order choice is a rule with margin (the fewest
    # states within min_gain of the best), so both processes give the same order, delay and model.
    first, second = _identified_with_kernel("Haswell"), _identified_with_kernel("Sandybridge")
    if first["kernels"] == second["kernels"]:
        pytest.skip(f"OPENBLAS_CORETYPE changes nothing here (kernels {first['kernels']} in both processes)")
    assert (first["order"], first["delay"]) == (second["order"], second["delay"])
    h1, h2 = (np.array(r["re"]) + 1j * np.array(r["im"]) for r in (first, second))
    assert np.max(np.abs(h1 - h2)) <= 1e-9 * np.max(np.abs(h1))
