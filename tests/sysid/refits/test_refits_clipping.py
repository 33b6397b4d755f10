"""refits: the clipping correction's refit on a session whose noise recording clips reaches the floor of
its unclipped twin (the excluded samples out of the output-error cost, ``refits._gap_aware``)."""

import numpy as np
import pytest
from conftest import SHORT
from effect_sessions import TEST_REFIT
from effect_sessions import WORKFLOW_OPTIONS as OPTIONS

from sysid.identify import identify
from sysid.io.recordings import Recording
from sysid.random_plant import random_session
from sysid.refine import refine
from sysid.validation.compare import compare


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
