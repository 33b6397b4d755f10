"""sysid.estimation.modal_parametrisation: the modal basis, the parametrisation of the poles, nearly real pairs split."""

import numpy as np

from sysid.core import lti
from sysid.estimation import modal_parametrisation
from sysid.estimation.output_error_data import BlockData


def test_modal_basis_is_the_resolvent_for_any_output_row(rng):
    # Written column by column in place: still C (zI - A)^-1 e_j, also for an output row other than [1 0 | 1].
    upper = 0.97 * np.exp(1j * np.array([0.2, 1.1]))
    A = lti.real_block_diagonal(np.concatenate([upper, np.conj(upper), [0.4]]))
    C = rng.standard_normal((1, 5))
    z = np.exp(1j * np.linspace(0.01, 3.0, 7))
    expected = np.array([C @ np.linalg.inv(zk * np.eye(5) - A) for zk in z])[:, 0, :]
    np.testing.assert_allclose(modal_parametrisation.modal_basis(A, C, z), expected, rtol=1e-12, atol=0)


def test_a_nearly_real_pair_is_split_into_two_real_poles():
    d = 0.015
    near = np.exp(-d) * np.exp(1e-7j)
    pair = 0.9 * np.exp(0.2j)
    poles = np.array([near, np.conj(near), pair, np.conj(pair), 0.5])
    split = modal_parametrisation.split_near_real_pairs(poles)
    assert split.size == poles.size
    np.testing.assert_allclose(np.sort(split[np.abs(split.imag) == 0].real),
                               np.sort([0.5, np.exp(-1.1 * d), np.exp(-0.9 * d)]))
    assert np.count_nonzero(np.isin(split, [pair, np.conj(pair)])) == 2
    # Nothing nearly real: returned as given.
    np.testing.assert_array_equal(modal_parametrisation.split_near_real_pairs(poles[2:]), poles[2:])


def _block(length):
    return BlockData(np.ones(1, complex), np.ones(1, complex), np.ones(1, complex), length, 48000.0)


def test_the_parameters_give_back_the_poles_inside_the_decay_bound():
    upper = np.array([0.9 * np.exp(0.3j), 0.99 * np.exp(2.0j)])
    poles = np.concatenate([upper, np.conj(upper), [0.5, -0.2]])
    margin = modal_parametrisation.decay_bound(_block(1000))
    params, pairs = modal_parametrisation.poles_to_params(poles, margin)
    assert (pairs, params.size) == (2, 6)
    np.testing.assert_allclose(modal_parametrisation.params_to_poles(params, pairs, margin), poles, rtol=1e-12)
    # However far the parameters run, every pole stays at or inside the bound (to rounding).
    far = modal_parametrisation.params_to_poles(np.array([-50.0, 1.0, 40.0]), 1, margin)
    assert np.all(-np.log(np.abs(far)) >= margin * (1 - 1e-9))


def test_pole_derivatives_match_central_differences():
    params, pairs, margin = np.array([-3.0, 0.4, -1.0, 2.1, 0.3]), 2, 1e-3
    derivatives = modal_parametrisation.pole_derivatives(params, pairs, margin)
    for k in range(params.size):
        step = np.zeros_like(params)
        step[k] = 1e-6
        moved = (modal_parametrisation.params_to_poles(params + step, pairs, margin)
                 - modal_parametrisation.params_to_poles(params - step, pairs, margin)) / 2e-6
        pole = k // 2 if k < 2 * pairs else k  # the pair's upper pole, or the real pole after the conjugates
        np.testing.assert_allclose(moved[pole], derivatives[k], rtol=1e-7)


def test_poles_at_the_radius_bound_are_told_from_those_inside():
    data = _block(1000)
    bound = np.exp(-modal_parametrisation.decay_bound(data))
    poles = np.array([bound, bound ** 1.005, bound ** 1.02, 0.5])
    np.testing.assert_array_equal(modal_parametrisation.radius_bound_mask(poles, data), [True, True, False, False])
    assert modal_parametrisation.at_radius_bound(poles, data)
    assert not modal_parametrisation.at_radius_bound(poles[2:], data)
