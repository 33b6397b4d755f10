"""Tests of the causal feed-forward bound within the design's rules (anc.ruled_bound)."""

from __future__ import annotations

import numpy as np
import pytest

from anc.disturbance import from_recording
from anc.limits import FeedforwardProblem
from anc.ruled_bound import TOLERANCE_DB, outside_gain_db, ruled_wiener

from control_cases import recording_with_anc_off, seed_pair

LIMIT_DB, GAIN_DB = 6.0, 30.0


@pytest.fixture(scope="module")
def problem() -> FeedforwardProblem:
    # The seed's true plants at latency 1: the Wiener filter has about 100 dB of gain outside 20 Hz-2 kHz.
    pair = seed_pair()
    disturbance = from_recording(recording_with_anc_off(pair.p, seconds=2.0), ff_model=pair.p).modelled()
    return FeedforwardProblem(pair.s, disturbance, 1, pair.p)


def _cost(problem, W) -> float:
    error = np.abs(problem.H + problem.G * W) ** 2 + problem.effort * np.abs(W) ** 2
    return float(np.sum(problem.band_measure * problem.phi * error))


def _louder_db(problem, W) -> np.ndarray:
    """Per band with noise, dB louder at the ear with W than without."""
    on = problem.band_sum(problem.uu + problem.phi * np.abs(problem.H + problem.G * W) ** 2)
    return (10.0 * np.log10(on / problem.off))[:problem.bands][problem.audible]


@pytest.fixture(scope="module")
def ruled(problem):
    return ruled_wiener(problem, LIMIT_DB, GAIN_DB)


def test_the_wiener_filter_breaks_the_rules_here(problem):
    assert outside_gain_db(problem, problem.wiener()) > GAIN_DB + 40.0


def test_the_filter_keeps_every_rule(problem, ruled):
    assert ruled.feasible
    assert ruled.outside_gain_db <= GAIN_DB + TOLERANCE_DB
    assert np.max(_louder_db(problem, ruled.W)) <= LIMIT_DB + TOLERANCE_DB


def test_it_is_the_optimum_the_dual_function_bounds(problem, ruled):
    # Strong duality: the feasible filter's J and the dual function's value meet.
    assert -TOLERANCE_DB <= ruled.gap_db <= 0.1
    assert "gain outside" in ruled.binding
    # The rules cost J: the unconstrained Wiener filter's is lower.
    assert _cost(problem, ruled.W) > _cost(problem, problem.wiener())


def test_rules_that_do_not_bind_give_the_wiener_filter(problem):
    loose = ruled_wiener(problem, 200.0, 200.0)
    assert loose.feasible and loose.binding == () and loose.iterations == 1
    np.testing.assert_allclose(problem.attenuation(loose.W), problem.attenuation(problem.wiener()), atol=1e-9)


def test_a_tighter_gain_bound_costs_more(problem, ruled):
    tighter = ruled_wiener(problem, LIMIT_DB, GAIN_DB - 20.0)
    assert tighter.feasible and tighter.outside_gain_db <= GAIN_DB - 20.0 + TOLERANCE_DB
    assert _cost(problem, tighter.W) > _cost(problem, ruled.W)
