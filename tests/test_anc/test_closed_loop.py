"""The sample-by-sample closed loop (``anc.closed_loop``): the loop law, the latency, prediction = achievement
on an exact model. Whole designs judged on the true plants are in ``test_design_closed_loop.py``."""

from __future__ import annotations

import numpy as np
import pytest
from control_cases import predicted_small_controller

from anc.closed_loop import closed_loop_poles, predicted_and_achieved, run_closed_loop
from anc.prediction import band_centres
from sysid.core.plants import appendix_a_model

CENTRES = np.array(band_centres())
CHECKED = (CENTRES >= 50.0) & (CENTRES <= 1000.0)


def _controller(s, p, latency: int = 2):
    return predicted_small_controller(s, p, latency)


def test_true_model_loop_equals_prediction():
    """With the internal model equal to the plant, achieved = predicted (the loop is open: d_hat = d)."""
    s, p = appendix_a_model("fb"), appendix_a_model("ff")
    controller = _controller(s, p)
    assert np.max(np.abs(closed_loop_poles(controller, s))) < 1.0
    predicted, achieved = predicted_and_achieved(controller, s, p, seconds=2.0, seed=3)
    assert set(achieved) == {"ff", "fb", "both"}
    for part in achieved:
        np.testing.assert_allclose(np.array(achieved[part])[CHECKED], np.array(predicted[part])[CHECKED], atol=1.0)


@pytest.mark.parametrize("latency", [1, 2, 5])
def test_latency_delays_the_drive(latency):
    """An impulse of disturbance moves the drive L samples later (y[k] = Q d_hat[k-L])."""
    s = appendix_a_model("fb")
    c = _controller(s, None, latency)
    d = np.zeros(64)
    d[0] = 1.0
    run = run_closed_loop(c, s, d, use_ff=False)
    assert np.all(run.y[: c.latency_samples] == 0.0)
    assert run.y[c.latency_samples] == pytest.approx(float(c.fb.D[0, 0]))
