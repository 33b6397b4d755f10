"""Designed on identified models, run on the true plants (issue 13's acceptance checks)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import FAST_OPTIONS, SHORT, short_spec

from anc import design
from anc.closed_loop import run_closed_loop, verify
from anc.design import undamped_pole
from anc.disturbance import default_disturbance
from anc.feedback import ROBUSTNESS_BOUND
from anc.prediction import band_centres
from anc.uncertainty import model_uncertainty
from sysid.core.errors import HelmetAncError
from sysid.core.plants import appendix_a_model
from sysid.identify import identify
from sysid.random_plant import random_plant, random_session
from sysid.simulate import simulate_session

CENTRES = np.array(band_centres())
CHECKED = (CENTRES >= 50.0) & (CENTRES <= 1000.0)


def _identified(session):
    return identify(session.noise, session.sweeps, session.spec.path, FAST_OPTIONS).model


class ShortOfTruth(AssertionError):
    """Stable and as predicted, but more than 1 dB below the design on the true plants (50 Hz-1 kHz)."""


def dense_usage(controller, uncertainty, bins=2**17):
    """r95 |S_model Q| of the stored Q on a grid 4 times finer than the design's dense check
    (``anc.feedback.dense_grid``) and 201 points over +-4 bandwidths of each model pole."""
    model, fs = controller.internal_model, controller.fs
    poles = np.linalg.eigvals(model.A)
    centre = np.abs(np.angle(poles)) * fs / (2 * np.pi)
    width = np.maximum(np.abs(np.log(np.abs(poles))) * fs / np.pi, 1e-6)
    f = np.concatenate((np.linspace(0.0, fs / 2, bins + 1),
                        (centre[:, None] + 4 * width[:, None] * np.linspace(-1, 1, 201)).reshape(-1)))
    f = f[(f >= 0) & (f <= fs / 2)]
    G = model.frequency_response(f) * np.exp(-2j * np.pi * f * controller.latency_samples / fs)
    return f, uncertainty.at(f) * np.abs(G * controller.fb.frequency_response(f, fs))


def _check(s_true, p_true, s_id, p_id, seed=0):
    """Issue 13's checks. The limit is the same design made on the true plants like for like: the same
    settings and the uncertainty band the design under test was given (the identified FB model's)."""
    disturbance = default_disturbance(s_id.fs, p_id)
    ours = design(s_id, p_id, disturbance)
    limit = design(s_true, p_true, default_disturbance(s_true.fs, p_true), uncertainty=model_uncertainty(s_id))
    f, usage = dense_usage(ours, model_uncertainty(s_id))
    assert usage.max() <= ROBUSTNESS_BOUND * (1 + 1e-9), \
        f"r95 |S_model Q| = {usage.max():.3f} at {f[np.argmax(usage)]:.3f} Hz, between the design's check points"
    results = verify(ours, limit, s_true, p_true, disturbance, seconds=2.0, seed=seed)
    for r in results:
        assert r.stable, f"{r.part}: closed loop unstable (largest pole {r.largest_pole:.6f})"
        worst = np.max(np.abs(r.achieved - r.predicted)[CHECKED])
        assert worst <= 2.0, f"{r.part}: achieved differs from predicted by {worst:.2f} dB in a band 50 Hz-1 kHz"
        gap = np.mean(r.limit[CHECKED]) - np.mean(r.achieved[CHECKED])
        if gap > 1.0:
            raise ShortOfTruth(f"{r.part}: {gap:.2f} dB below the true-plant design on average 50 Hz-1 kHz")
    return results


def test_seed_plants_identified_match_truth(identifications):
    s_true, p_true = appendix_a_model("fb"), appendix_a_model("ff")
    results = _check(s_true, p_true, identifications["fb"].model, identifications["ff"].model)
    assert {r.part for r in results} == {"ff", "fb", "both"}


def _random_pair(seed):
    """A random helmet: FB path of `seed`, FF path of the next seed drawn at the same rate."""
    s = random_plant(seed, "fb")
    other = seed + 1000
    while random_plant(other, "ff").fs != s.fs:
        other += 1
    return seed, other


def _check_random(seed):
    """Checks of a random helmet; a model with no uncertainty band that validates far above its noise
    floor must be refused (one with a band is designed within it)."""
    fb_seed, ff_seed = _random_pair(seed)
    s_session = random_session(fb_seed, "fb", **SHORT)
    p_session = random_session(ff_seed, "ff", **SHORT)
    s_id, p_id = _identified(s_session), _identified(p_session)
    poor = [m for m in (s_id, p_id)
            if m.uncertainty is None and m.identification["rms"] > 3.0 * m.identification["noise_floor"]]
    if poor:
        with pytest.raises(HelmetAncError, match="noise floor"):
            design(s_id, p_id)
        return
    if undamped_pole(s_id) is not None:
        # An identification defect (a mode within 1e-6 of the unit circle): refused, with the reason.
        with pytest.raises(HelmetAncError, match="undamped pole"):
            design(s_id, p_id)
        return
    _check(s_session.plant, p_session.plant, s_id, p_id, seed=seed)


# Helmets whose design is stable and achieves what it predicts but falls more than 1 dB short of the
# like-for-like design on the true plants, and why (BENCHMARKS.md, Control). None at present: 5 and 7
# come within 1 dB (7: the FF band rule and the FF model's gain capped outside its band; 5: the limit
# made with the identified model's band). A helmet whose identified FB model has an undamped pole
# (radius 1 - 1e-9, ``anc.design.UNDAMPED_MARGIN``; 9 and 1 with identify as of 9675620, 2 as of
# 435c1fd) is checked to be refused instead.
SHORT_OF_TRUTH: dict[int, str] = {}


def _random_cases(seeds):
    return [pytest.param(seed, marks=pytest.mark.xfail(strict=True, raises=ShortOfTruth, reason=SHORT_OF_TRUTH[seed]))
            if seed in SHORT_OF_TRUTH else seed for seed in seeds]


@pytest.mark.parametrize("seed", _random_cases([3]))
def test_random_plants_identified_match_truth(seed):
    _check_random(seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", _random_cases([1, 2, 4, 5, *range(6, 13)]))
def test_random_plants_identified_match_truth_slow(seed):
    _check_random(seed)


def test_true_model_loop_equals_prediction():
    """With the internal model equal to the plant, achieved = predicted (the loop is open: d_hat = d)."""
    s, p = appendix_a_model("fb"), appendix_a_model("ff")
    c = design(s, p)
    results = verify(c, c, s, p, default_disturbance(s.fs, p), seconds=2.0, seed=3)
    for r in results:
        np.testing.assert_allclose(r.achieved[CHECKED], r.predicted[CHECKED], atol=1.0)
        np.testing.assert_array_equal(r.achieved, r.limit)


def test_latency_delays_the_drive():
    """An impulse of disturbance moves the drive L samples later (y[k] = Q d_hat[k-L])."""
    s = appendix_a_model("fb")
    c = design(s, None)
    d = np.zeros(64)
    d[0] = 1.0
    run = run_closed_loop(c, s, d)
    assert np.all(run.y[: c.latency_samples] == 0.0)
    assert run.y[c.latency_samples] == pytest.approx(float(c.fb.D[0, 0]))
