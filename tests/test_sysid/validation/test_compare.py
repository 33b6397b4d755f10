"""compare: the true plant sits at the noise floor; a wrong model shows where it fails."""

import copy
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import short_spec

from sysid.core.errors import IdentificationError
from sysid.simulate import simulate_session
from sysid.validation.compare import compare, format_comparison, third_octave_bands
from sysid.validation.sweeps import simulated_rms


@pytest.fixture(scope="module")
def clean():
    return simulate_session(short_spec("ff", 11))


class TestCompare:
    def test_true_plant_is_at_the_noise_floor(self, clean):
        c = compare(clean.plant, clean.sweeps)
        assert c.rms == pytest.approx(simulated_rms(clean.plant, clean.sweeps), rel=1e-9)
        assert 0.9 < c.ratio < 1.1
        assert c.fit_percent > 99.0
        assert c.rms_full >= c.rms

    def test_bands_are_third_octaves_from_20_hz_to_5_khz(self, clean):
        c = compare(clean.plant, clean.sweeps)
        centers = [b["center_hz"] for b in c.bands]
        assert len(centers) == 25 and centers[0] == pytest.approx(19.95, rel=1e-3) and centers[-1] == pytest.approx(5012, rel=1e-3)
        assert all(0.6 < b["ratio"] < 1.6 for b in c.bands)

    def test_residual_tests_pass_for_the_true_plant(self, clean):
        c = compare(clean.plant, clean.sweeps)
        assert c.lags.tolist() == list(range(25)) and c.cross_lags.tolist() == list(range(-24, 25))
        assert c.residual_autocorrelation[0] == pytest.approx(1.0)
        assert np.sum(np.abs(c.residual_autocorrelation[1:]) > c.autocorrelation_bound) <= 2
        assert np.sum(np.abs(c.residual_input_crosscorrelation) > c.crosscorrelation_bound) <= 2

    def test_a_missing_delay_shows_at_positive_cross_lags_and_in_bands(self):
        session = simulate_session(short_spec("ff", 11), effects=["delay:10"])
        plant = session.plant
        plant.delay = 0
        c = compare(plant, session.sweeps)
        outside = np.abs(c.residual_input_crosscorrelation) > c.crosscorrelation_bound
        assert np.any(outside[c.cross_lags > 0]) and c.ratio > 10
        assert "above the noise floor" in format_comparison(c)

    def test_disturbance_model_removes_the_hum_from_residual_and_floor(self):
        session = simulate_session(short_spec("ff", 11), effects=["periodic-disturbance:50,2,1e-3"])
        plant = session.plant
        raw = compare(plant, session.sweeps)
        plant.disturbance_frequencies = [50.0, 100.0]
        modelled = compare(plant, session.sweeps)
        # The floor leaves the lines out either way (validation.noise_floor): the hum is error, not noise.
        assert raw.noise_floor == pytest.approx(modelled.noise_floor, rel=0.01)
        assert raw.ratio > 5 and 0.9 < modelled.ratio < 1.2

    def test_floor_does_not_follow_the_model_inside_a_stretch_excluded_in_one_repeat(self, clean):
        # An excluded stretch holds the model's prediction; excluded in the first repeat only, the
        # repeats' difference there would hold the model's error against the second's measurement.
        first = Path(str(clean.sweeps[0].path)).name
        floors = []
        for gain in (1.0, 30.0):
            model = copy.deepcopy(clean.plant)
            model.C = model.C * gain
            model.D = model.D * gain
            model.excluded = {first: [[0.2, 0.5]]}
            floors.append(compare(model, clean.sweeps).noise_floor)
        unexcluded = compare(clean.plant, clean.sweeps).noise_floor
        assert floors[1] == pytest.approx(floors[0], rel=1e-9)
        assert floors[0] == pytest.approx(unexcluded, rel=0.1)

    def test_to_dict_is_json_without_signals(self, clean):
        data = compare(clean.plant, clean.sweeps).to_dict()
        text = json.dumps(data, allow_nan=False)
        assert "per_sweep" not in data and len(text) < 20000

    def test_needs_two_sweeps(self, clean):
        with pytest.raises(IdentificationError, match="exactly two"):
            compare(clean.plant, clean.sweeps[:1])


def test_third_octave_band_edges_touch():
    bands = third_octave_bands()
    for (_, _, upper), (_, lower, _) in zip(bands, bands[1:]):
        assert upper == pytest.approx(lower)
