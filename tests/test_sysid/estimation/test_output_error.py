"""Output-error refinement on raw DFT data (with the block transient term)."""

import numpy as np
import pytest

from sysid.core import lti
from sysid.core.errors import IdentificationError
from sysid.core.plants import appendix_a_model
from sysid.estimation import modal_parametrisation, output_error
from sysid.estimation.output_error import block_data, refine_output_error
from sysid.io.recordings import Recording


def _noise_recording(model, rng, seconds=1.0, output_noise=0.0):
    u = rng.standard_normal(int(seconds * model.fs)) * 0.1
    y = model.simulate(u) + output_noise * rng.standard_normal(u.size)
    # Start mid-stream so the block transient term is really needed.
    start = int(0.2 * model.fs)
    return Recording(u[start:], y[start:], model.fs, "noise")


def test_recovers_the_plant_from_perturbed_poles_without_noise(rng):
    plant = appendix_a_model("ff")
    data = block_data(_noise_recording(plant, rng), max_seconds=None)
    poles = np.linalg.eigvals(plant.A)
    perturbed = lti.real_block_diagonal(poles * (1 - 0.003) * np.exp(0.02j * np.sign(poles.imag)))
    C = np.ones((1, 5))
    fit = refine_output_error(perturbed, np.ones((5, 1)), C, np.zeros((1, 1)), data)
    assert fit.cost_after < 1e-12 * fit.cost_before
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(fit.A)), np.sort_complex(poles), atol=1e-6)
    f = np.linspace(20, 5000, 50)
    z = np.exp(2j * np.pi * f / plant.fs)
    np.testing.assert_allclose(lti.frequency_response(fit.A, fit.B, fit.C, fit.D, z), plant.frequency_response(f), rtol=1e-5)


def test_result_is_stable_and_never_worse_than_the_start(rng):
    plant = appendix_a_model("fb")
    data = block_data(_noise_recording(plant, rng, output_noise=1e-3), max_seconds=None)
    start = lti.real_block_diagonal(np.array([0.9, 0.5 + 0.5j, 0.5 - 0.5j]))
    fit = refine_output_error(start, np.ones((3, 1)), np.ones((1, 3)), np.zeros((1, 1)), data, max_iterations=10)
    assert lti.spectral_radius(fit.A) < 1
    assert fit.cost_after <= fit.cost_before


def test_unstable_start_is_rejected(rng):
    data = block_data(_noise_recording(appendix_a_model("ff"), rng, seconds=0.5), max_seconds=None)
    with pytest.raises(IdentificationError, match="needs a stable starting model"):
        refine_output_error(np.array([[1.1]]), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1)), data)


def test_noise_tolerance_stops_early_at_the_same_cost_within_one_noise_variance(rng):
    # Started 0.3 % off the poles of the appendix-A FF plant with output noise: the default
    # tolerance iterates on for gains far below sigma^2 = V / N; the noise tolerance stops
    # sooner, and what it leaves is less than one sigma^2 (1/N of the cost) above.
    plant = appendix_a_model("ff")
    data = block_data(_noise_recording(plant, rng, seconds=2.0, output_noise=1e-3), max_seconds=None)
    poles = np.linalg.eigvals(plant.A)
    start = lti.real_block_diagonal(poles * (1 - 0.003) * np.exp(0.01j * np.sign(poles.imag)))
    args = (start, np.ones((5, 1)), np.ones((1, 5)), np.zeros((1, 1)), data)
    full = refine_output_error(*args)
    quick = refine_output_error(*args, noise_tolerance=True)
    residuals = 2 * data.z.size
    assert quick.iterations < full.iterations
    assert quick.cost_after <= full.cost_after * (1 + 1.0 / residuals)
    assert quick.cost_after < 0.5 * quick.cost_before


def test_jacobian_matches_central_differences_in_and_out_of_band(rng):
    # The closed-form derivatives of the block bases, in band and out of it (pairs at 1.5 and
    # 2.9 rad/sample lie outside the 20 Hz-5 kHz bins of a 48 kHz block).
    data = block_data(_noise_recording(appendix_a_model("ff"), rng, seconds=0.5, output_noise=1e-3), max_seconds=None)
    upper = 0.99 * np.exp(1j * np.array([0.01, 0.6, 1.5, 2.9]))
    poles = np.concatenate([upper, np.conj(upper), [0.5, -0.3]])
    problem = output_error._Problem(data, 0, False)
    x, pairs = modal_parametrisation.poles_to_params(poles, modal_parametrisation.decay_bound(data))
    projection = output_error._Projection(problem, pairs)
    jacobian = projection.jacobian(x)
    for k in range(x.size):
        h = 1e-6 * max(1.0, abs(x[k]))
        step = np.zeros_like(x)
        step[k] = h
        numeric = (projection.residual(x + step) - projection.residual(x - step)) / (2 * h)
        assert np.linalg.norm(jacobian[:, k] - numeric) <= 1e-3 * np.linalg.norm(numeric)



def test_the_jacobians_in_place_passes_give_the_bits_of_the_plain_expressions(rng):
    # The order search's decisions hang on the last bits (a changed product moved random helmet 4's order).
    z = np.exp(1j * np.linspace(0.01, 3.0, 501))[None, :]
    u = (rng.standard_normal(501) + 1j * rng.standard_normal(501))[None, :]
    poles = (0.9 * np.exp(1j * rng.uniform(0, 3, 4)))[:, None]
    on_u, on_z = rng.standard_normal((4, 1)), rng.standard_normal((4, 1))
    assert np.array_equal(output_error._inverse_square(z, poles), (1.0 / (z - poles)) ** 2)
    assert np.array_equal(output_error._linear_in_theta(u, z, on_u, on_z), u * on_u + z * on_z)



def test_spare_poles_stay_within_what_the_block_resolves(rng):
    # A spare pair and two real poles started next to z = -1 and z = 1: out of the fitted band
    # nothing holds them; the decay bound keeps every pole at or inside what the block resolves.
    plant = appendix_a_model("ff")
    data = block_data(_noise_recording(plant, rng, seconds=1.0, output_noise=1e-3), max_seconds=None)
    spare = np.array([0.9999 * np.exp(3.1j), 0.9999 * np.exp(-3.1j), -0.9999, 0.99999])
    poles = np.concatenate([np.linalg.eigvals(plant.A), spare])
    n = poles.size
    fit = refine_output_error(lti.real_block_diagonal(poles), np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)),
                              data, max_iterations=20)
    found = np.linalg.eigvals(fit.A)
    decay = -np.log(np.maximum(np.abs(found), 1e-300))
    assert np.all(decay >= modal_parametrisation.decay_bound(data) * (1 - 1e-6))
    # With the bound at 1 - 1e-9 everywhere (before), a spare pair ran to |p| = 1 - 1e-9 at 13.4 kHz and two real
    # poles to z = 1 - 1e-9 on this block.
    assert np.max(np.abs(found)) < 1 - 1e-5


def test_a_lightly_damped_bass_mode_stays_reachable(rng):
    # Q 50 at 30 Hz and 48 kHz: 1 - |p| = 3.9e-5, above the bound 1/L = 2.1e-5 of a 1 s block.
    fs, omega = 48000.0, 2 * np.pi * 30.0 / 48000.0
    pole = np.exp(-omega / (2 * 50.0) + 1j * omega)
    A = lti.real_block_diagonal(np.array([pole, np.conj(pole), 0.6]))
    B, C, D = np.array([[1e-3], [2e-3], [0.3]]), lti.block_output_row(A), np.zeros((1, 1))
    u = rng.standard_normal(int(1.5 * fs)) * 0.1
    y = lti.simulate(A, B, C, D, u)
    data = block_data(Recording(u[int(0.5 * fs):], y[int(0.5 * fs):], fs, "noise"), max_seconds=None)
    start = lti.real_block_diagonal(np.array([pole * 0.9999 * np.exp(0.002j), np.conj(pole) * 0.9999 * np.exp(-0.002j), 0.5]))
    fit = refine_output_error(start, np.zeros((3, 1)), np.zeros((1, 3)), np.zeros((1, 1)), data)
    assert fit.cost_after < 1e-12 * fit.cost_before
    found = np.linalg.eigvals(fit.A)
    assert np.min(np.abs(found - pole)) < 1e-7


def test_added_pole_costs_equal_the_fixed_pole_cost_of_the_joined_poles(rng):
    data = block_data(_noise_recording(appendix_a_model("fb"), rng, seconds=0.5, output_noise=1e-3), max_seconds=None)
    base = lti.real_block_diagonal(np.array([0.99 * np.exp(0.05j), 0.99 * np.exp(-0.05j), 0.8]))
    added = [np.array([r * np.exp(1j * w), r * np.exp(-1j * w)]) for r, w in ((0.995, 0.01), (0.9, 0.3), (0.99, 0.05))]
    added.append(np.array([0.3]))
    costs = output_error.added_pole_costs(base, added, data)
    for cost, extra in zip(costs, added):
        joined = lti.real_block_diagonal(np.concatenate([np.linalg.eigvals(base), extra]))
        assert cost == pytest.approx(output_error.linear_cost(joined, data), rel=1e-8)





def test_a_pair_run_to_the_real_axis_refines_to_the_two_real_poles_it_imitated(rng):
    # Two real poles (roll-off corners) and a mode; the start holds the real poles as a pair at
    # angle 1e-9: the pair parametrisation cannot leave the upper half plane, split it can
    # (``split_near_real``, as the final refinement of ``identify`` asks).
    poles = np.array([0.6, 0.7, 0.98 * np.exp(0.1j), 0.98 * np.exp(-0.1j)])
    A = lti.real_block_diagonal(poles)
    B, C, D = np.array([[0.3], [-0.2], [0.01], [0.02]]), lti.block_output_row(A), np.zeros((1, 1))
    fs = 48000.0
    u = rng.standard_normal(int(0.6 * fs)) * 0.1
    y = lti.simulate(A, B, C, D, u)
    data = block_data(Recording(u[int(0.1 * fs):], y[int(0.1 * fs):], fs, "noise"), max_seconds=None)
    near = 0.65 * np.exp(1e-9j)
    start = lti.real_block_diagonal(np.array([near, np.conj(near), poles[2] * 0.999, poles[3] * 0.999]))
    fit = refine_output_error(start, np.zeros((4, 1)), np.zeros((1, 4)), np.zeros((1, 1)), data, split_near_real=True)
    assert fit.cost_after < 1e-12 * fit.cost_before
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(fit.A)), np.sort_complex(poles), atol=1e-6)


def test_minpack_takes_the_iterates_of_least_squares_lm(rng):
    # refine_output_error calls MINPACK's lmder through leastsq (no Jacobian evaluated again at the
    # result): the same iterates, evaluations and result as least_squares(method="lm", x_scale="jac").
    import scipy.optimize

    plant = appendix_a_model("fb")
    data = block_data(_noise_recording(plant, rng, seconds=0.5, output_noise=1e-3), max_seconds=None)
    poles = np.linalg.eigvals(plant.A)
    start = lti.real_block_diagonal(poles * (1 - 0.003) * np.exp(0.01j * np.sign(poles.imag)))
    n = start.shape[0]
    fit = refine_output_error(start, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), data, max_iterations=15,
                              noise_tolerance=True)
    margin = modal_parametrisation.decay_bound(data)
    params, pairs = modal_parametrisation.poles_to_params(np.linalg.eigvals(start), margin)
    projection = output_error._Projection(output_error._Problem(data, 0, False), pairs)
    reference = scipy.optimize.least_squares(projection.residual, params, jac=projection.jacobian, method="lm",
                                             x_scale="jac", max_nfev=15, ftol=1.0 / (2 * data.z.size))
    assert fit.iterations == reference.nfev
    assert fit.cost_after == pytest.approx(float(np.sum(reference.fun**2)), rel=1e-12)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(fit.A)),
                               np.sort_complex(modal_parametrisation.params_to_poles(reference.x, pairs, margin)), rtol=1e-10)


def test_a_trial_point_that_is_not_finite_gets_a_residual_the_optimiser_rejects(rng):
    # MINPACK's step computation can break down and propose NaN parameters from a finite residual and
    # Jacobian: the residual there is finite and far above the last one, and the last point's state stands.
    data = block_data(_noise_recording(appendix_a_model("ff"), rng, seconds=0.5, output_noise=1e-3), max_seconds=None)
    poles = np.concatenate([0.99 * np.exp(1j * np.array([0.01, 0.6])), 0.99 * np.exp(-1j * np.array([0.01, 0.6])), [0.5]])
    x, pairs = modal_parametrisation.poles_to_params(poles, modal_parametrisation.decay_bound(data))
    projection = output_error._Projection(output_error._Problem(data, 0, False), pairs)
    before = projection.residual(x)
    broken = projection.residual(np.full_like(x, np.nan))
    assert np.all(np.isfinite(broken)) and np.linalg.norm(broken) > 1e3 * np.linalg.norm(before)
    np.testing.assert_array_equal(projection.residual(x), before)
    A, C, theta, residual = projection.linear(x)
    assert np.all(np.isfinite(theta)) and np.all(np.isfinite(residual))
