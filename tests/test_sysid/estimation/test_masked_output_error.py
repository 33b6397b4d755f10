"""masked_output_error: the core refined over the kept samples only, the excluded ones out of the cost."""

import numpy as np
import pytest

from sysid.core import lti
from sysid.estimation.masked_output_error import refine_masked, refine_masked_inputs

FS = 44100.0


def plant(poles):
    A = lti.real_block_diagonal(np.asarray(poles))
    rng = np.random.default_rng(3)
    return A, np.ones((A.shape[0], 1)), rng.standard_normal((1, A.shape[0])), np.zeros((1, 1))


def pair(radius, f_hz):
    p = radius * np.exp(2j * np.pi * f_hz / FS)
    return [p, np.conj(p)]


POLES = pair(0.9995, 68.0) + [0.6] + pair(0.99, 1000.0)


def gapped(seed: int = 0):
    """(input, clean ear signal, noise std, kept samples, recorded ear) of the plant POLES: the loudest
    30 % of the samples are missing (as where a channel clips) and stand at zero."""
    rng = np.random.default_rng(seed)
    A, B, C, D = plant(POLES)
    v = 0.1 * rng.standard_normal(60000)
    clean = lti.simulate(A, B, C, D, v)
    noise = 1e-3 * np.std(clean)
    keep = np.abs(clean) < np.quantile(np.abs(clean), 0.7)
    y = np.where(keep, clean + noise * rng.standard_normal(v.size), 0.0)
    return v, clean, noise, keep, y


def test_poles_and_prediction_from_the_kept_samples_where_the_gaps_hold_the_loud_ones():
    v, clean, noise, keep, y = gapped()
    start = lti.real_block_diagonal(np.array(POLES) * np.array([0.9999, 0.9999, 0.9, 1.002, 1.002]))
    fit = refine_masked(start, v, y, keep)
    assert fit.cost_after < fit.cost_before
    # At the noise: the kept samples' cost is their noise energy, and the prediction matches the clean
    # response everywhere, in the gaps too (what is missing is the ear signal, not the input).
    assert fit.cost_after <= 1.05 * noise**2 * np.count_nonzero(keep)
    predicted = lti.simulate(fit.A, fit.B, fit.C, fit.D, v)
    assert np.sqrt(np.mean((predicted - clean)[~keep] ** 2)) < noise
    found = np.sort_complex(np.linalg.eigvals(fit.A))
    assert np.allclose(found, np.sort_complex(np.array(POLES)), atol=2e-3)


def test_a_fit_that_counts_the_gaps_is_pulled_off_the_plant():
    # The same data with every sample counted (the gaps as recorded, at zero): the cost cannot reach the
    # noise and the poles move; so the mask is what makes the first test pass.
    v, clean, noise, keep, y = gapped()
    A = lti.real_block_diagonal(np.array(POLES))
    fit = refine_masked(A, v, y, np.ones(v.size, bool))
    assert fit.cost_after > 100 * noise**2 * v.size


def test_feedthrough_and_a_real_pole_only():
    rng = np.random.default_rng(1)
    A = np.array([[0.8]])
    B, C, D = np.ones((1, 1)), np.array([[0.5]]), np.array([[0.3]])
    v = rng.standard_normal(20000)
    y = lti.simulate(A, B, C, D, v) + 1e-4 * rng.standard_normal(v.size)
    keep = rng.random(v.size) > 0.5
    fit = refine_masked(np.array([[0.7]]), v, y, keep, feedthrough=True)
    assert fit.A[0, 0] == pytest.approx(0.8, abs=1e-4)
    assert fit.D[0, 0] == pytest.approx(0.3, abs=1e-4)


def test_common_poles_with_a_numerator_per_input():
    # A Hammerstein path v + 0.5 v^2 through the plant POLES: two inputs, one core, numerators C and 0.5 C;
    # the loudest 30 % of the ear samples missing. Fitted free, each input's numerator and the common poles
    # come back, and the numerators are the rank-one pair the map makes.
    rng = np.random.default_rng(2)
    A, B, C, D = plant(POLES)
    v = 0.1 * rng.standard_normal(60000)
    clean = lti.simulate(A, B, C, D, v + 0.5 * v**2)
    keep = np.abs(clean) < np.quantile(np.abs(clean), 0.7)
    y = np.where(keep, clean + 1e-3 * np.std(clean) * rng.standard_normal(v.size), 0.0)
    start = lti.real_block_diagonal(np.array(POLES) * np.array([0.9999, 0.9999, 0.9, 1.002, 1.002]))
    A_fit, B_fit, C_fit, D_fit = refine_masked_inputs(start, np.stack([v, v**2], axis=1), y, keep)
    assert C_fit.shape == (2, 5) and D_fit.shape == (2,)
    found = np.sort_complex(np.linalg.eigvals(A_fit))
    assert np.allclose(found, np.sort_complex(np.array(POLES)), atol=2e-3)
    assert np.allclose(C_fit[1], 0.5 * C_fit[0], atol=1e-3 * np.max(np.abs(C_fit[0])))
    predicted = lti.simulate(A_fit, B_fit, C_fit[:1], np.zeros((1, 1)), v) + \
        lti.simulate(A_fit, B_fit, C_fit[1:], np.zeros((1, 1)), v**2)
    assert np.sqrt(np.mean((predicted - clean)[~keep] ** 2)) < 1e-2 * np.std(clean)
