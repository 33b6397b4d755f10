"""Removal of degenerate states from an identified model (sysid.estimation.reduction)."""

from types import SimpleNamespace

import numpy as np
import pytest

from sysid.core import lti
from sysid.estimation.output_error import block_data, decay_bound, radius_bound_mask
from sysid.estimation.reduction import (Reduced, is_balanced, truncation_orders, without_degenerate_states,
                                       without_spare_pole)
from sysid.io.recordings import Recording

FS = 8000.0
BAND = (20.0, 3000.0)
Z = np.exp(2j * np.pi * np.linspace(20.0, 3000.0, 300) / FS)


def _plant():
    """Two modes (300 Hz Q 8, 1.2 kHz Q 15), balanced."""
    poles = []
    for f, q in ((300.0, 8.0), (1200.0, 15.0)):
        p = np.exp(2 * np.pi * f / FS * (-1 / (2 * q) + 1j))
        poles += [p, np.conj(p)]
    A = lti.real_block_diagonal(np.array(poles))
    return lti.balanced_realisation(A, [[0.05], [0.02], [-0.03], [0.04]], lti.block_output_row(A), 0.0)


@pytest.fixture(scope="module")
def session():
    """One second of noise through the plant (output noise 1e-3) as a block, and a validation rms of a
    model on a further half second."""
    plant = _plant()
    rng = np.random.default_rng(5)
    u = rng.standard_normal(int(1.5 * FS))
    y = lti.simulate(*plant, u) + 1e-3 * rng.standard_normal(u.size)
    n = int(FS)
    block = block_data(Recording(u[:n], y[:n], FS, "noise.wav"), BAND, max_seconds=1.0)
    calls = []

    def validate(model):
        calls.append(model)
        return float(np.sqrt(np.mean((lti.simulate(model.A, model.B, model.C, model.D, u[n:]) - y[n:]) ** 2)))

    return plant, block, validate, calls


def test_poles_parked_at_the_radius_bound_are_dropped_and_the_rest_refitted(session):
    plant, block, validate, calls = session
    # The plant with a pole at z = 1 and one at z = -1, both at the block's bound, residues cancelling in band.
    edge = np.exp(-decay_bound(block))
    A = np.zeros((6, 6))
    A[:4, :4], A[4, 4], A[5, 5] = plant[0], edge, -edge
    B = np.vstack([plant[1], [[1e-5], [1e-5]]])
    C = np.hstack([plant[2], [[1.0, 1.0]]])
    assert np.count_nonzero(radius_bound_mask(np.linalg.eigvals(A), block)) == 2
    rms = validate(SimpleNamespace(A=A, B=B, C=C, D=np.zeros((1, 1))))
    calls.clear()
    reduced = without_degenerate_states(A, B, C, np.zeros((1, 1)), rms, block, validate, min_gain=0.03)
    assert reduced.A.shape == (4, 4) and "2 poles at the radius bound dropped" in reduced.removed
    assert len(calls) == 1 and reduced.rms == pytest.approx(validate(reduced)) and reduced.rms <= 1.03 * rms
    assert not np.any(radius_bound_mask(np.linalg.eigvals(reduced.A), block))
    assert is_balanced(reduced.A, reduced.B, reduced.C)
    h_true, h = lti.frequency_response(*plant, Z), lti.frequency_response(reduced.A, reduced.B, reduced.C, reduced.D, Z)
    assert np.max(np.abs(h - h_true)) < 0.02 * np.max(np.abs(h_true))


def test_a_model_without_degenerate_states_is_returned_as_it_is(session):
    plant, block, validate, calls = session
    calls.clear()
    reduced = without_degenerate_states(*plant, 1e-3, block, validate, min_gain=0.03)
    assert reduced.removed == "" and reduced.rms == 1e-3 and not calls
    for got, given in zip((reduced.A, reduced.B, reduced.C, reduced.D), plant):
        np.testing.assert_array_equal(got, given)


def test_states_no_balanced_realisation_holds_are_truncated_without_a_refit(session):
    _, block, validate, calls = session
    # Four real poles within 1e-3 of 0.9 holding an order-3 response (Newton coefficients 0.1, 0.01,
    # 0.001, 0) in modal form: residues of 1e4 that cancel, one state carrying nothing.
    p = 0.9 + np.array([0.0, 2e-4, 5e-4, 9e-4])
    newton = [1e-1, 1e-2, 1e-3, 0.0]
    r = [sum(newton[k] / np.prod([p[i] - p[j] for j in range(k + 1) if j != i]) for k in range(i, 4)) for i in range(4)]
    A, B, C = np.diag(p), np.array(r)[:, None], np.ones((1, 4))
    assert not is_balanced(*lti.balanced_realisation(A, B, C, 0.0)[:3])
    calls.clear()
    reduced = without_degenerate_states(A, B, C, np.zeros((1, 1)), 1e-3, block, validate, min_gain=0.03)
    assert reduced.A.shape == (3, 3) and "1 state of negligible Hankel singular value left out" in reduced.removed
    assert not calls and reduced.rms == 1e-3
    assert max(np.abs(reduced.A).max(), np.abs(reduced.B).max(), np.abs(reduced.C).max()) < 1.0 + 1e-9
    h_modal, h = lti.frequency_response(A, B, C, 0.0, Z), lti.frequency_response(reduced.A, reduced.B, reduced.C, reduced.D, Z)
    assert np.max(np.abs(h - h_modal)) < 1e-7 * np.max(np.abs(h_modal))


def test_truncation_orders_are_the_lowest_whose_removed_values_sum_below_each_fraction():
    hsv = np.array([1.0, 0.5, 0.1, 5e-4, 3e-4, 2e-5, 1e-5])
    # Removed from order 3: 8.3e-4 <= 1e-3; from order 5: 3e-5 <= 1e-4.
    assert truncation_orders(hsv) == [3, 5]
    assert truncation_orders(np.array([1.0, 0.5, 0.1])) == []


def _with_faint_mode(plant, residue):
    """The plant beside a 2.5 kHz mode of Q 5 whose residue is ``residue``, balanced."""
    p = np.exp(2 * np.pi * 2500.0 / FS * (-1 / 10 + 1j))
    A = np.zeros((6, 6))
    A[:4, :4], A[4:, 4:] = plant[0], lti.real_block_diagonal(np.array([p, np.conj(p)]))
    B = np.vstack([plant[1], [[residue], [0.0]]])
    C = np.hstack([plant[2], [[1.0, 0.0]]])
    return lti.balanced_realisation(A, B, C, plant[3])


def test_a_state_the_validation_does_not_miss_is_truncated(session):
    plant, block, validate, calls = session
    model = _with_faint_mode(plant, 1e-5)
    rms = validate(SimpleNamespace(A=model[0], B=model[1], C=model[2], D=model[3]))
    calls.clear()
    reduced = without_degenerate_states(*model, rms, block, validate, min_gain=0.03)
    # Truncated, then refined on the block at its new order (the least-squares fit of that order, which the
    # band of identify's model assumes): two validations.
    assert reduced.A.shape == (4, 4) and reduced.removed == "balanced truncation 6 -> 4, refined"
    assert len(calls) == 2 and reduced.rms <= 1.01 * rms
    assert is_balanced(reduced.A, reduced.B, reduced.C)
    h, h_full = (lti.frequency_response(*m, Z) for m in ((reduced.A, reduced.B, reduced.C, reduced.D), model))
    assert np.max(np.abs(h - h_full)) < 1e-3 * np.max(np.abs(h_full))


def test_a_truncation_the_validation_rejects_is_not_kept(session):
    plant, block, _, _ = session
    model = _with_faint_mode(plant, 1e-5)
    # A validation that sees the faint mode: every truncation validates 10 % worse.
    calls = []

    def validate(candidate):
        calls.append(candidate)
        return 1.1e-3

    reduced = without_degenerate_states(*model, 1e-3, block, validate, min_gain=0.03)
    assert reduced.A.shape == (6, 6) and reduced.removed == "" and len(calls) >= 1
    np.testing.assert_array_equal(reduced.A, model[0])


def _with_real_pole(plant, pole, residue):
    """The plant beside a real pole ``pole`` whose residue is ``residue``, balanced."""
    A = np.zeros((5, 5))
    A[:4, :4], A[4, 4] = plant[0], pole
    return lti.balanced_realisation(A, np.vstack([plant[1], [[residue]]]), np.hstack([plant[2], [[1.0]]]), plant[3])


def test_a_spare_pole_out_of_the_band_is_dropped_and_the_rest_refitted(session):
    plant, block, validate, calls = session
    # A pole at z = -0.995 (4 kHz, out of the 20 Hz-3 kHz band): its state the largest in the balanced model.
    model = _with_real_pole(plant, -0.995, 0.05)
    assert lti.hankel_singular_values(*model[:3])[0] > 2 * lti.hankel_singular_values(*plant[:3])[0]
    rms = validate(SimpleNamespace(A=model[0], B=model[1], C=model[2], D=model[3]))
    calls.clear()
    reduced = without_spare_pole(Reduced(*model, rms), BAND, block, validate)
    assert reduced.A.shape == (4, 4) and reduced.removed == "an out-of-band pole dropped"
    assert len(calls) == 1 and reduced.rms <= rms
    h_true, h = lti.frequency_response(*plant, Z), lti.frequency_response(reduced.A, reduced.B, reduced.C, reduced.D, Z)
    assert np.max(np.abs(h - h_true)) < 0.02 * np.max(np.abs(h_true))


def test_an_out_of_band_pole_the_validation_needs_is_kept(session):
    plant, block, _, _ = session
    model = _with_real_pole(plant, -0.995, 5e-3)
    # A validation that sees the pole: the refit without it validates 10 % worse.
    calls = []

    def validate(candidate):
        calls.append(candidate)
        return 1.1e-3

    given = Reduced(*model, 1e-3)
    assert without_spare_pole(given, BAND, block, validate) is given and len(calls) == 1
