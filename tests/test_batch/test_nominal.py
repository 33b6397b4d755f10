"""The nominal model of a helmet and its multiplicative bound (batch.nominal), and the
rider variants that make a helmet's members (batch.riders)."""

from __future__ import annotations

import numpy as np
import pytest

from batch import RiderSpread, nominal_model, rider_variant, run_batch, write_simulated_campaign
from sysid.core.errors import HelmetAncError
from sysid.core.model import Model
from sysid.random_plant import random_plant
from tests.batch_sessions import BATCH_OPTIONS, SHORT_SESSION

F = np.geomspace(20.0, 5000.0, 200)


class TestRiderVariant:
    def test_modes_move_by_the_spread_and_order_is_kept(self):
        plant = random_plant(3, "fb").model
        variant = rider_variant(plant, seed=1)
        assert variant.order == plant.order and variant.delay == plant.delay and variant.stable
        before = np.sort(np.abs(np.angle(plant.poles())))
        after = np.sort(np.abs(np.angle(variant.poles())))
        moved = after[before > 0] / before[before > 0]
        assert np.all(np.abs(moved - 1) < 0.1) and np.any(np.abs(moved - 1) > 1e-4)

    def test_no_spread_is_the_plant(self):
        plant = random_plant(5, "ff").model
        same = rider_variant(plant, seed=2, spread=RiderSpread(0.0, 0.0, 0.0))
        np.testing.assert_allclose(same.frequency_response(F), plant.frequency_response(F), rtol=1e-8)

    def test_seeded(self):
        plant = random_plant(3, "fb").model
        np.testing.assert_array_equal(rider_variant(plant, 7).A, rider_variant(plant, 7).A)


class TestNominalModel:
    @pytest.fixture(scope="class")
    def members(self):
        plant = random_plant(6, "fb").model
        return [rider_variant(plant, seed=k) for k in range(6)]

    def test_bound_covers_every_member_exactly_given(self, members):
        nominal = nominal_model(members)
        assert np.all(nominal.coverage([m.frequency_response(nominal.frequencies_hz) for m in members]) == 1.0)
        assert nominal.model.stable
        assert nominal.model.order <= max(m.order for m in members) + 4

    def test_bound_is_the_largest_member_distance(self, members):
        nominal = nominal_model(members)
        h_n = nominal.model.frequency_response(nominal.frequencies_hz)
        distances = np.array([np.abs(m.frequency_response(nominal.frequencies_hz) - h_n) / np.abs(h_n) for m in members])
        np.testing.assert_allclose(nominal.relative_bound, distances.max(axis=0), rtol=1e-9)

    def test_members_own_bands_widen_the_bound(self, members):
        plain = nominal_model(members)
        banded = []
        for m in members:
            data = m.to_dict()
            data["uncertainty"] = {"frequencies_hz": [10.0, 10000.0], "relative_95": [0.05, 0.05]}
            banded.append(Model.from_dict(data))
        wide = nominal_model(banded)
        assert wide.model.identification["members_with_own_band"] == len(members)
        f = wide.frequencies_hz
        h_n = wide.model.frequency_response(f)
        spread = np.array([np.abs(m.frequency_response(f) - h_n) + 0.05 * np.abs(m.frequency_response(f)) for m in members])
        np.testing.assert_allclose(wide.relative_bound, spread.max(axis=0) / np.abs(h_n), rtol=1e-9)
        assert np.mean(wide.relative_bound) > np.mean(plain.relative_bound)

    def test_identical_members_give_a_tight_bound(self):
        plant = random_plant(3, "fb").model
        nominal = nominal_model([plant, plant, plant])
        assert np.max(nominal.relative_bound) < 1e-3

    def test_needs_two_members_of_one_path(self, members):
        with pytest.raises(HelmetAncError, match="at least two members"):
            nominal_model(members[:1])
        other = random_plant(6, "ff").model
        with pytest.raises(HelmetAncError, match="members must share path and sample rate"):
            nominal_model([members[0], other])


def _coverage_of_identified_members(tmp_path, helmets: int, heads: int, seed: int, options, **session):
    truths = write_simulated_campaign(tmp_path / "s", helmets=helmets, heads=heads, path="fb", seed=seed, **session)
    result = run_batch(tmp_path / "s", tmp_path / "out", workers=2, options=options)
    assert result.failed == 0, [r["reason"] for r in result.rows]
    coverage = {}
    for (helmet, path), nominal in result.nominals.items():
        for row in (r for r in result.rows if r["helmet"] == helmet):
            truth = truths[f"{helmet}/{row['head']}/{path}"]
            coverage[row["session"]] = float(nominal.coverage(truth.frequency_response(nominal.frequencies_hz))[0])
    return result, coverage


def test_bound_covers_true_responses_of_identified_members(tmp_path):
    """One random helmet on four heads, identified from short sessions: the bound from the
    identified models covers each head's TRUE response at >= 95 % of frequencies."""
    result, coverage = _coverage_of_identified_members(tmp_path, 1, 4, seed=3, options=BATCH_OPTIONS, latency=False,
                                                       **SHORT_SESSION)
    # The members must be good models for the claim to mean anything.
    assert all(r["rms_over_floor"] < 2.0 for r in result.rows), [r["rms_over_floor"] for r in result.rows]
    assert min(coverage.values()) >= 0.95, coverage


@pytest.mark.slow
def test_bound_covers_true_responses_on_several_random_helmets(tmp_path):
    """Four random helmets (latency included) on six heads each, thesis-length sessions, default options."""
    _, coverage = _coverage_of_identified_members(tmp_path, 4, 6, seed=3, options=None)
    assert min(coverage.values()) >= 0.95, coverage
