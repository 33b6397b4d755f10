"""The order/error/cost curve (sysid.estimation.order_curve). The FABIAN HRIR ships in sysid/core/data (Brinkmann
et al., TU Berlin, CC BY 4.0)."""

import numpy as np
import pytest

from sysid.core.board import board_cost
from sysid.estimation.long_response import fir_estimate, frequency_limited_truncation
from sysid.estimation.long_route import core_rms
from sysid.estimation.order_curve import OrderCurve, ladder, ladder_grid
from sysid.simulate import measured_session
from sysid.validation.sweeps import noise_floor, sweep_spectrum


def test_the_grid_holds_every_low_order_then_a_geometric_step():
    grid = ladder_grid(400)
    assert grid[:12] == list(range(1, 13)) and grid[-1] == 400
    steps = np.diff(grid[12:]) / np.asarray(grid[12:-1])
    assert np.all(steps[:-1] > 0.1) and np.all(steps < 0.2)
    assert ladder_grid(5) == [1, 2, 3, 4, 5]


def _curve():
    return OrderCurve([1, 2, 4, 8, 16], [10.0, 5.0, 1.5, 1.04, 1.0], 1.0, np.array([1.0, 0.5, 0.1, 0.01, 1e-3]),
                      "test")


def test_the_lowest_order_at_the_floor_and_under_a_cap():
    curve = _curve()
    # Within MIN_GAIN (3 %) of the best (1.0) or within 1.02 of the floor: 8 (1.04) is not, 16 is.
    assert curve.lowest_at_floor(1.02, 0.03) == 16
    assert curve.lowest_at_floor(1.1, 0.03) == 8
    # Under a cap of 4: the best among 1, 2, 4 is 4.
    assert curve.lowest_at_floor(1.02, 0.03, cap=4) == 4


def test_the_stored_curve_holds_the_board_cost_of_every_order():
    curve = _curve()
    curve.refined[8] = 1.01
    curve.chosen = 8
    stored = curve.to_dict()
    assert stored["orders"] == [1, 2, 4, 8, 16] and stored["chosen"] == 8
    assert stored["q15_step"] == [round(board_cost(n).step, 1) for n in stored["orders"]]
    assert stored["refined_orders"] == [8] and stored["refined_ratio"] == [1.01]
    assert stored["hankel_singular_values"][0] == 1.0


@pytest.fixture(scope="module")
def fabian():
    session = measured_session("fabian_left_az60", noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)
    noise = session.noise
    taps = fir_estimate(noise.u, noise.y, noise.fs, 160, int(3.0 * noise.fs)).taps
    spectra = [sweep_spectrum(s) for s in session.sweeps]
    return frequency_limited_truncation(taps, noise.fs, (0.0, 5000.0)), spectra, noise_floor(*session.sweeps)


def test_the_ladder_finds_the_lowest_order_at_the_floor(fabian):
    truncation, spectra, floor = fabian
    curve = ladder(truncation, spectra, floor)
    n = curve.lowest_at_floor()
    # Issue 25: 1.09x the floor at 30 states; 10 states are far above it.
    assert 12 < n <= 40
    assert curve.ratio(n) < 1.2 < curve.ratio(10)
    # The compressed validation agrees with the exact one at the order chosen.
    system, _ = truncation.system(n)
    assert core_rms(system, spectra) / floor == pytest.approx(curve.ratio(n), rel=0.05)
