"""Tests of the spectral factorisation, the causal Wiener filter and the per-band limits (anc.wiener, anc.limits)."""

from __future__ import annotations

import numpy as np
import pytest

from anc.disturbance import from_recording
from anc.limits import Limits, feedforward_limits
from anc.wiener import FFTGrid, allpass_split, causal_part, causal_wiener, minimum_phase
from sysid.core.errors import HelmetAncError

from control_cases import JUDGED_HZ, recording_with_anc_off, seed_pair

POINTS = 4096


def _response(taps, points: int = POINTS) -> np.ndarray:
    return np.fft.rfft(np.asarray(taps, dtype=float), points)


class TestMinimumPhase:
    def test_a_minimum_phase_filters_spectrum_factors_back_to_it(self):
        taps = [1.0, -0.5, 0.2]  # zeros at radius sqrt(0.2): inside the unit circle
        B = _response(taps)
        L = minimum_phase(np.abs(B) ** 2, POINTS)
        np.testing.assert_allclose(L, B, atol=1e-9)

    def test_the_factor_of_a_non_minimum_phase_filter_is_its_reflection(self):
        # 1 - 2 z^-1 has its zero at z = 2; the minimum-phase filter of the same magnitude is 2 - z^-1.
        L = minimum_phase(np.abs(_response([1.0, -2.0])) ** 2, POINTS)
        np.testing.assert_allclose(L, _response([2.0, -1.0]), atol=1e-9)

    def test_a_spectrum_with_a_zero_is_refused(self):
        power = np.ones(POINTS // 2 + 1)
        power[10] = 0.0
        with pytest.raises(ValueError, match="positive"):
            minimum_phase(power, POINTS)


class TestAllpassSplit:
    def test_delay_and_outside_zero_go_to_the_allpass(self):
        # S = z^-3 (1 - 2 z^-1): G_mp = 2 - z^-1, G_ap = z^-3 (1 - 2 z^-1) / (2 - z^-1).
        S = _response([0.0, 0.0, 0.0, 1.0, -2.0])
        G_ap, G_mp = allpass_split(S, POINTS, floor=1e-14)
        np.testing.assert_allclose(G_mp, _response([2.0, -1.0]), rtol=1e-6)
        np.testing.assert_allclose(np.abs(G_ap), 1.0, atol=1e-6)
        np.testing.assert_allclose(G_ap * G_mp, S, atol=1e-9)

    def test_causal_part_keeps_the_first_half_of_the_circular_response(self):
        impulse = np.zeros(POINTS)
        impulse[[2, POINTS - 3]] = [1.0, 5.0]  # one sample at t = 2, one at t = -3
        kept = np.fft.irfft(causal_part(np.fft.rfft(impulse), POINTS), POINTS)
        np.testing.assert_allclose(kept[[2, POINTS - 3]], [1.0, 0.0], atol=1e-12)


class TestCausalWiener:
    def test_a_delayed_drive_path_cancels_a_slower_chin_path_exactly(self):
        # T = z^-5 H0, G = z^-2: W = -z^-3 H0 is causal and cancels everything.
        H0 = [1.0, 0.3, -0.2]
        T = _response([0.0] * 5 + H0)
        G = _response([0.0, 0.0, 1.0])
        W = causal_wiener(G, T, np.ones(POINTS // 2 + 1), POINTS)
        np.testing.assert_allclose(W, -_response([0.0] * 3 + H0), atol=1e-9)

    def test_one_sample_behind_it_is_the_one_step_predictor(self):
        # Reference AR(1), M = 1 / (1 - a z^-1); G = z^-1, T = 1: W = -[z M]_+ / M = -a (Kailath et al. sec. 7.3).
        a = 0.8
        M = 1.0 / (1.0 - a * np.exp(-2j * np.pi * np.arange(POINTS // 2 + 1) / POINTS))
        W = causal_wiener(_response([0.0, 1.0]), np.ones(POINTS // 2 + 1, complex), np.abs(M) ** 2, POINTS)
        np.testing.assert_allclose(W, -a, atol=1e-9)

    def test_grid_is_long_enough_for_the_slowest_pole(self):
        grid = FFTGrid.for_paths(48000.0, np.array([0.9999]))
        assert grid.points >= 8.0 / -np.log(0.9999)


@pytest.fixture(scope="module")
def seed_limits() -> Limits:
    pair = seed_pair()
    disturbance = from_recording(recording_with_anc_off(pair.p), ff_model=pair.p).modelled()
    return feedforward_limits(pair.s, disturbance, 1)


class TestSeedLimits:
    def test_the_seeds_causal_bound_is_the_reference_value(self, seed_limits):
        # Issue 26: 11.2 dB mean 50 Hz-1 kHz (pink chin noise 20 Hz-2 kHz, -40 dB incoherent, latency 1).
        assert abs(seed_limits.mean("causal_ff", *JUDGED_HZ) - 11.2) <= 1.0

    def test_the_coherence_bound_is_the_incoherent_floors(self, seed_limits):
        assert abs(seed_limits.mean("coherence", *JUDGED_HZ) - 40.0) <= 1.5

    def test_the_causal_bound_is_below_the_coherence_bound(self, seed_limits):
        for causal, coherence in zip(seed_limits.causal_ff_db, seed_limits.coherence_db):
            if causal is not None:
                assert causal <= coherence + 0.5

    def test_the_zero_of_s_outside_the_unit_circle_is_named(self, seed_limits):
        named = [r for c, r in zip(seed_limits.bands_hz, seed_limits.reasons) if 50.0 <= c <= 500.0]
        assert named and all("z = 1.0089" in r for r in named)

    def test_json_round_trip(self, seed_limits):
        assert Limits.from_dict(seed_limits.to_dict()) == seed_limits

    def test_a_record_of_another_format_is_refused(self, seed_limits):
        data = seed_limits.to_dict()
        data["format"] = "something else"
        with pytest.raises(HelmetAncError, match="not a limits record"):
            Limits.from_dict(data)
        data = seed_limits.to_dict()
        data["reasons"] = data["reasons"][:-1]
        with pytest.raises(HelmetAncError, match="reasons"):
            Limits.from_dict(data)

    def test_a_negative_latency_is_refused(self):
        pair = seed_pair()
        disturbance = from_recording(recording_with_anc_off(pair.p, seconds=1.0), ff_model=pair.p).modelled()
        with pytest.raises(HelmetAncError, match="latency"):
            feedforward_limits(pair.s, disturbance, -1)


class TestWithinTheRules:
    def test_the_bound_within_the_rules_is_recorded_and_lower(self, seed_limits):
        ruled = seed_limits.causal_ff_ruled_db
        assert ruled is not None and len(ruled) == len(seed_limits.bands_hz)
        assert seed_limits.mean("causal_ff_ruled", *JUDGED_HZ) < seed_limits.mean("causal_ff", *JUDGED_HZ) - 0.5
        within = seed_limits.details["within_rules"]
        assert within["feasible"] and within["outside_gain_db"] <= within["max_gain_db"] + 0.1
        assert seed_limits.details["bound_outside_gain_db"] > within["max_gain_db"] + 40.0

    def test_the_reason_states_the_gain_the_bound_needs(self, seed_limits):
        stated = [(ruled, reason) for bound, ruled, reason in zip(seed_limits.causal_ff_db,
                                                                  seed_limits.causal_ff_ruled_db, seed_limits.reasons)
                  if bound is not None and bound - ruled >= 1.0]
        assert len(stated) >= 5
        for ruled, reason in stated:
            assert f"within the design's rules {ruled:.1f} dB" in reason and "outside 20 Hz-2 kHz" in reason

    def test_a_record_without_it_still_loads(self, seed_limits):
        data = seed_limits.to_dict()
        del data["causal_ff_ruled_db"]
        assert Limits.from_dict(data).causal_ff_ruled_db is None
