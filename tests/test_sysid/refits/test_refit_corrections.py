"""refits.corrections: the refit behind data corrections (``_corrected_refit``), and the clipping correction's refit
on a session whose noise recording clips, which reaches the floor of its unclipped twin (the excluded samples out
of the output-error cost, ``_gap_aware``)."""

import numpy as np
import pytest
from conftest import SHORT
from effect_sessions import TEST_REFIT
from effect_sessions import WORKFLOW_OPTIONS as OPTIONS

from sysid.core.errors import IdentificationError
from sysid.core.model import Model
from sysid.identify import identify
from sysid.io.recordings import Recording
from sysid.random_plant import random_session
from sysid.refine import refine
from sysid.refits import corrections
from sysid.refits.corrections import _corrected_refit
from sysid.validation.compare import compare

TRANSIENT_S = 0.5


def test_a_correction_whose_starts_are_all_unstable_returns_the_trial_for_the_caller_to_refuse(monkeypatch):
    # The trial (corrections applied, core kept) and its warm start both unstable, and no stable model in the
    # fresh fit's grid: the unstable trial comes back (refine's _refinement refuses it in one line), not a
    # ValueError from choosing among no candidates.
    session = random_session(3, noise_duration=4.0, sweep_duration=1.0, sweep_silence=0.2)
    trial = Model(path="fb", fs=session.noise.fs, A=np.array([[1.01]]), B=np.array([[1.0]]), C=np.array([[0.1]]),
                  D=np.zeros((1, 1)), delay=3)
    fresh_calls = []

    def no_stable_model(*args):
        fresh_calls.append(args)
        raise IdentificationError("no stable model in the grid")

    monkeypatch.setattr(corrections, "_warm", lambda t, *args: t)
    monkeypatch.setattr(corrections, "_fresh", no_stable_model)
    result = _corrected_refit(trial, session.noise, session.sweeps, TEST_REFIT, TRANSIENT_S)
    assert result is trial and not result.stable
    assert len(fresh_calls) == 1


def clipped_noise(recording: Recording, fraction: float) -> Recording:
    """The recording with its ear channel flat-topped at the level its loudest ``fraction`` of samples exceed."""
    level = float(np.quantile(np.abs(recording.y), 1.0 - fraction))
    return Recording(recording.u, np.clip(recording.y, -level, level), recording.fs, recording.path)


@pytest.mark.slow
def test_a_clipped_noise_recording_refits_to_the_floor_of_its_unclipped_twin():
    # Random helmet 101 FB, its noise recording (driven louder than the sweeps) flat-topped at 2 % of its
    # samples: the detector's margins leave out 63 % of the recording. Filled with the prediction of the
    # model before (EM) the refit ended at 6.7x the floor; with the gaps out of the cost, at the twin's.
    twin = random_session(101, "fb", **SHORT)
    noise = clipped_noise(twin.noise, 0.02)
    unclipped = compare(identify(twin.noise, twin.sweeps, "fb", OPTIONS).model, twin.sweeps)
    model = identify(noise, twin.sweeps, "fb", OPTIONS).model
    result = refine(model, noise, twin.sweeps, "clipping", TEST_REFIT)
    assert result.step.params["excluded_fraction"][0] > 0.02
    assert result.after.ratio <= max(1.2 * unclipped.ratio, 1.2), (result.after.ratio, unclipped.ratio)
