"""Models out of the order search's output-error fits are balanced (sysid.estimation.order_search, sysid.estimation.output_error).

The order search refines starts built from poles of neighbouring orders; two poles can
land almost on one another, and the modal form with a unit output row then holds the
response only through huge, cancelling entries of B (1e9-1e12 on random helmets), above
the model file's limit (``sysid.core.model.MAX_COEFFICIENT``): identify used to raise there.
A search stalled above the floor gets the mode it missed inserted (``_insert_modes``), and
one near the floor gets nothing. Starts hold no two coinciding poles and none at the block's
radius bound (``distinct_start``).
"""

import numpy as np
import pytest
import scipy.signal

from sysid.core import lti
from sysid.core.model import MAX_COEFFICIENT, Model
from sysid.core.thresholds import START_REAL_POLES, START_SEPARATION
from sysid.estimation import order_search
from sysid.estimation.order_search import (OrderCandidate, _insert_modes, _pair, block_at_noise, distinct_start,
                                           sweep_rms, without_freed_pole)
from sysid.estimation.subspace import SubspaceDecomposition
from sysid.estimation.output_error import at_radius_bound, block_data, decay_bound, linear_cost, refine_output_error
from sysid.io.recordings import Recording
from sysid.validation.sweeps import sweep_spectrum

FS = 44100.0
Z = np.exp(1j * np.linspace(0.01, 3.0, 200))
# A double pole at 0.9 (two equal roll-off corners give one): G(z) = 1 / (z - 0.9)^2.
A_TRUE = np.array([[0.9, 1.0], [0.0, 0.9]])
B_TRUE = np.array([[0.0], [1.0]])
C_TRUE = np.array([[1.0, 0.0]])


def _data():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(int(FS))
    y = lti.simulate(A_TRUE, B_TRUE, C_TRUE, 0.0, u) + 1e-4 * rng.standard_normal(u.size)
    return block_data(Recording(u, y, FS), (20.0, 20000.0), 1.0)


@pytest.mark.parametrize("gap", [1e-6, 1e-4])
def test_fit_with_nearly_coincident_poles_is_balanced(gap):
    # Held at poles 0.9 and 0.9 + gap (one iteration), the modal B is about 1 / gap.
    start = lti.real_block_diagonal(np.array([0.9, 0.9 + gap]))
    fit = refine_output_error(start, np.zeros((2, 1)), np.zeros((1, 2)), np.zeros((1, 1)), _data(), max_iterations=1)
    assert max(np.abs(fit.A).max(), np.abs(fit.B).max(), np.abs(fit.C).max()) < 10.0
    truth = lti.frequency_response(A_TRUE, B_TRUE, C_TRUE, 0.0, Z)
    assert np.max(np.abs(lti.frequency_response(fit.A, fit.B, fit.C, fit.D, Z) - truth)) < 1e-3 * np.max(np.abs(truth))
    # Both Gramians equal and diagonal: the balanced realisation.
    wc, wo = lti.gramians(fit.A, fit.B, fit.C)
    assert np.max(np.abs(wc - wo)) < 1e-6 * np.max(np.abs(wc))
    Model(path="fb", fs=FS, A=fit.A, B=fit.B, C=fit.C, D=fit.D)


def test_fit_too_close_to_balance_is_still_within_the_model_limit():
    # At a gap of 1e-9 the modal B is 1e9 and the Gramians are lost to round-off; the
    # diagonal equalisation still brings the entries to about 3e4.
    start = lti.real_block_diagonal(np.array([0.9, 0.9 + 1e-9]))
    fit = refine_output_error(start, np.zeros((2, 1)), np.zeros((1, 2)), np.zeros((1, 1)), _data(), max_iterations=1)
    largest = max(np.abs(fit.A).max(), np.abs(fit.B).max(), np.abs(fit.C).max())
    assert largest < 1e-3 * MAX_COEFFICIENT
    Model(path="fb", fs=FS, A=fit.A, B=fit.B, C=fit.C, D=fit.D)


# A plant of two modes, 35 Hz Q 7 and 500 Hz Q 20 (sysid.estimation.order_search._insert_modes): a model
# of the 500 Hz mode alone has stalled far above the floor, as the scan does on random helmets
# whose lightly damped mode below 60 Hz no start found.
_MODES = ((35.0, 7.0), (500.0, 20.0))


def _two_mode_plant():
    poles = np.concatenate([_pair(2 * np.pi * f / FS, q) for f, q in _MODES])
    A = lti.real_block_diagonal(poles)
    C = lti.block_output_row(A)
    B = np.ones((4, 1))
    # Each mode's own peak gain 1: scale its B entries by its response at its frequency.
    for k, (f, _) in enumerate(_MODES):
        Bk = np.zeros((4, 1))
        Bk[2 * k:2 * k + 2] = 1.0
        B[2 * k:2 * k + 2] /= abs(lti.frequency_response(A, Bk, C, 0.0, np.array([np.exp(2j * np.pi * f / FS)]))[0])
    return A, B, C, np.zeros((1, 1))


def _insertion_case():
    rng = np.random.default_rng(1)
    A, B, C, D = _two_mode_plant()
    noise = 1e-3
    u = rng.standard_normal(int(FS))
    block = block_data(Recording(u, lti.simulate(A, B, C, D, u) + noise * rng.standard_normal(u.size), FS),
                       (20.0, 5000.0), 1.0)
    t = np.arange(int(FS)) / FS
    sweeps = []
    for _ in range(2):
        x = 0.5 * scipy.signal.chirp(t, 20.0, t[-1], 5000.0, method="logarithmic")
        y = lti.simulate(A, B, C, D, x) + noise * rng.standard_normal(x.size)
        sweeps.append(sweep_spectrum(Recording(x, y, FS), (20.0, 4000.0), skip_s=0.0))
    floor = sweep_rms(A, B, C, D, sweeps)
    fit = refine_output_error(lti.real_block_diagonal(_pair(2 * np.pi * 500.0 / FS, 20.0)), np.zeros((2, 1)), np.zeros((1, 2)),
                              np.zeros((1, 1)), block)
    stalled = OrderCandidate(2, "500 Hz only", sweep_rms(fit.A, fit.B, fit.C, fit.D, sweeps), fit.A, fit.B, fit.C, fit.D)
    return block, sweeps, floor, stalled


def test_a_stalled_search_gets_the_missing_mode_inserted():
    block, sweeps, floor, stalled = _insertion_case()
    assert stalled.rms > 10 * floor
    best = {2: stalled}
    _insert_modes(best, block, sweeps, floor, max_order=30, feedthrough=False, max_iterations=20,
                  min_gain=0.03)
    assert best[4].rms <= 1.2 * floor
    frequencies = np.abs(np.angle(np.linalg.eigvals(best[4].A))) * FS / (2 * np.pi)
    assert np.min(np.abs(frequencies - 35.0)) < 2.0
    assert "mode at" in best[4].start


def test_a_search_near_the_floor_gets_nothing_inserted():
    block, sweeps, floor, stalled = _insertion_case()
    # The same stalled model, with the floor said to be where it already validates.
    best = {2: stalled}
    _insert_modes(best, block, sweeps, stalled.rms, max_order=30, feedthrough=False, max_iterations=20,
                  min_gain=0.03)
    assert list(best) == [2] and best[2] is stalled


def test_the_true_plants_residual_is_at_the_blocks_noise_level():
    block, sweeps, floor, _ = _insertion_case()
    A, _, _, _ = _two_mode_plant()
    assert block_at_noise(A, block, sweeps, floor, feedthrough=False)
    # The same residual against a floor said to be 10 % lower is above it (3 sigma is 5 % here).
    assert not block_at_noise(A, block, sweeps, 0.9 * floor, feedthrough=False)


def test_a_model_missing_a_bass_mode_is_not_at_the_blocks_noise_level():
    # The stalled model lacks the 35 Hz mode: its residual on the 1 s block stays above the
    # noise, so the search's patience for plateaus far above the floor still applies to it.
    block, sweeps, floor, stalled = _insertion_case()
    assert not block_at_noise(stalled.A, block, sweeps, floor, feedthrough=False)


def test_a_plateau_far_above_the_floor_gets_the_mode_inserted_before_the_scan_goes_on(monkeypatch):
    # With the residual-mode start held at 3 kHz no start of orders 1-5 holds the 35 Hz mode and the
    # scan stalls at about 130x the floor (order 7's real-pole start finds it later). One order without
    # gain (insert_patience=1) brings in the insertion, which reaches the floor: the scan ends there.
    block, sweeps, floor, _ = _insertion_case()
    monkeypatch.setattr(order_search, "_residual_mode", lambda poles, block, feedthrough: _pair(2 * np.pi * 3000.0 / FS, 10.0))
    candidates = order_search.search_orders(block, sweeps, {}, {}, range(1, 31), floor, insert_patience=1)
    assert min(c.rms for c in candidates[:5]) > 100 * floor
    assert candidates[-1].order == 6 and "mode at 35 Hz" in candidates[-1].start
    assert candidates[-1].rms <= 1.2 * floor


# A plant of a 500 Hz mode (Q 20) and two real poles, 0.9 and 0.3 (roll-off corners).
_PAIR_500 = _pair(2 * np.pi * 500.0 / FS, 20.0)


def _real_pole_block():
    A = lti.real_block_diagonal(np.concatenate([_PAIR_500, [0.9, 0.3]]))
    rng = np.random.default_rng(1)
    u = rng.standard_normal(int(FS))
    y = lti.simulate(A, np.ones((4, 1)), lti.block_output_row(A), 0.0, u)
    return A, block_data(Recording(u, y + 1e-3 * rng.standard_normal(u.size), FS), (20.0, 5000.0), 1.0)


def _min_distance(poles):
    distance = np.abs(poles[:, None] - poles[None, :])
    return np.min(distance[~np.eye(poles.size, dtype=bool)])


def test_coinciding_and_bound_starting_poles_are_replaced_by_distinct_real_poles():
    _, block = _real_pole_block()
    bound = -np.exp(-decay_bound(block))
    # The chain's degenerate starts: the added 0.5 twice, two poles at z = 0, a spare pole run to z = -1.
    degenerate = np.concatenate([_PAIR_500, [0.5, 0.5, 0.0, 0.0, bound]])
    start = distinct_start(degenerate, block, feedthrough=False, added=1)
    assert start.size == degenerate.size + 1
    assert _min_distance(start) >= START_SEPARATION
    assert not at_radius_bound(start, block)
    # The pair and the first of each coinciding group stay; the replacements are real poles.
    np.testing.assert_array_equal(start[:4], np.concatenate([_PAIR_500, [0.5, 0.0]]))
    assert np.all(start[4:].imag == 0) and set(start[4:].real) <= set(START_REAL_POLES)


def test_a_start_without_degenerate_poles_is_kept_and_takes_the_added_pole_at_one_half():
    _, block = _real_pole_block()
    poles = np.concatenate([_PAIR_500, [0.9]])
    np.testing.assert_array_equal(distinct_start(poles, block, feedthrough=False), poles)
    np.testing.assert_array_equal(distinct_start(poles, block, feedthrough=False, added=1), np.append(poles, 0.5))


def test_a_model_holding_one_half_gets_another_real_pole_and_refines_to_the_truths_cost():
    # The order search's 'order n-1 + real pole' start from a model that already holds the added
    # pole 0.5: the new pole goes elsewhere, and the refinement reaches the true poles' cost.
    A_true, block = _real_pole_block()
    start = distinct_start(np.concatenate([_PAIR_500, [0.5]]), block, feedthrough=False, added=1)
    assert start.size == 4 and _min_distance(start) >= START_SEPARATION
    fit = refine_output_error(lti.real_block_diagonal(start), np.zeros((4, 1)), np.zeros((1, 4)), np.zeros((1, 1)),
                              block, max_iterations=20, noise_tolerance=True)
    assert fit.cost_after <= 1.001 * linear_cost(A_true, block)
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(fit.A).real)[:2], [0.3, 0.9], atol=1e-3)


def test_candidates_carry_the_grid_gamma_of_their_start():
    # Smoothed-FRF decompositions at two widths (here of the true response): a candidate refined from a
    # ``grid gamma=G`` start carries G as data (identify's provenance reads it there), the others none.
    block, sweeps, floor, _ = _insertion_case()
    A, B, C, D = _two_mode_plant()
    omega = 2 * np.pi * np.linspace(20.0, 5000.0, 300) / FS
    g = lti.frequency_response(A, B, C, D, np.exp(1j * omega))
    decompositions = {gamma: SubspaceDecomposition(omega, g, q=10) for gamma in (30, 100)}
    candidates = order_search.search_orders(block, sweeps, decompositions, {4: 100}, range(1, 5), floor)
    for c in candidates:
        assert c.gamma == (int(c.start.split("=")[1]) if c.start.startswith("grid gamma=") else None)
    assert any(c.gamma is not None for c in candidates)


def test_freed_pole_dropped_is_the_out_of_band_one_nearest_the_unit_circle():
    fs = 48000.0
    mode = 0.99 * np.exp(2j * np.pi * 1000.0 / fs)  # 1 kHz, in band
    high_pass = np.exp(-2 * np.pi * 5.0 / fs)  # 5 Hz coupling corner, out of band
    freed = 1 - 1e-9  # run to z = 1
    poles = np.array([mode, np.conj(mode), high_pass, freed, 0.3])
    kept = without_freed_pole(poles, (20.0, 5000.0), fs)
    assert sorted(np.round(np.abs(kept), 9)) == sorted(np.round(np.abs([mode, mode, high_pass, 0.3]), 9))
    # A pair out of band goes with its conjugate; nothing out of band: nothing to drop.
    pair = 0.999 * np.exp(2j * np.pi * 10.0 / fs)
    assert without_freed_pole(np.array([mode, np.conj(mode), pair, np.conj(pair)]), (20.0, 5000.0), fs).size == 2
    assert without_freed_pole(np.array([mode, np.conj(mode)]), (20.0, 5000.0), fs) is None
    # The only pole or pair out of band: dropping it leaves no core to refit, so nothing is dropped.
    assert without_freed_pole(np.array([pair, np.conj(pair)]), (20.0, 5000.0), fs) is None
    assert without_freed_pole(np.array([freed, 0.9999999]), (20.0, 5000.0), fs).size == 1
