"""Hidden effects of synthetic sessions: parsing, truth records and their signatures in the data."""

import numpy as np
import pytest
from conftest import short_spec

from sysid.core.effect_spec import parse_effect
from sysid.core.errors import HelmetAncError
from sysid.core.structures import factor_response, resonance_factor
from sysid.simulate import SIMULATED_EFFECTS, simulate_session


class TestParseEffect:
    def test_positional_and_named_parameters(self):
        spec = parse_effect("resonance:3000,q=5", SIMULATED_EFFECTS)
        assert spec.params == {"f0_hz": 3000.0, "q": 5.0, "gain_db": 10.0}

    def test_defaults_fill_missing_parameters(self):
        assert parse_effect("delay", SIMULATED_EFFECTS).params == {"samples": 23}

    @pytest.mark.parametrize("text, message", [
        ("wobble:3", "unknown effect 'wobble'"),
        ("delay:2.5", "samples must be a whole number"),
        ("delay:0", "samples must be between 1 and 2000"),
        ("resonance:3000,q=x", "'x' is not a number"),
        ("delay:1,2", "at most 1 parameter"),
        ("delay:speed=3", "unknown parameter 'speed'"),
    ])
    def test_bad_specs_are_one_line_errors(self, text, message):
        with pytest.raises(HelmetAncError, match=message):
            parse_effect(text, SIMULATED_EFFECTS)


def test_every_kind_simulates_and_is_recorded_in_truth():
    for kind in SIMULATED_EFFECTS:
        session = simulate_session(short_spec("ff", 1, noise_duration=4.0, sweep_duration=0.5), effects=[kind])
        assert [e["effect"] for e in session.truth["effects"]] == [kind]
        for recording in (session.noise, *session.sweeps):
            assert np.all(np.isfinite(recording.y)) and np.max(np.abs(recording.y)) <= 1.0


def test_a_session_without_effects_is_unchanged_by_the_effect_machinery():
    plain = simulate_session(short_spec("fb", 4, noise_duration=4.0, sweep_duration=0.5))
    again = simulate_session(short_spec("fb", 4, noise_duration=4.0, sweep_duration=0.5), effects=[])
    assert np.array_equal(plain.noise.y, again.noise.y)
    assert plain.truth["effects"] == []


def test_same_kind_twice_is_rejected():
    with pytest.raises(HelmetAncError, match="given twice"):
        simulate_session(short_spec("ff", 1, noise_duration=4.0), effects=["delay:3", "delay:4"])


def test_delay_shifts_the_true_plant():
    session = simulate_session(short_spec("ff", 1, noise_duration=4.0, sweep_duration=0.5), effects=["delay:17"])
    assert session.plant.delay == 17
    impulse = session.plant.simulate(np.eye(1, 64, 0)[0])
    assert np.all(impulse[:18] == 0) and impulse[18] != 0


def test_resonance_factor_has_the_stated_peak():
    b, a = resonance_factor(3400.0, 8.0, 10.0, 44100.0)
    gain = np.abs(factor_response(b, a, [3400.0, 20.0, 20000.0], 44100.0))
    assert gain == pytest.approx([10 ** 0.5, 1.0, 1.0], rel=1e-2)


def test_clipping_puts_samples_on_the_rails():
    session = simulate_session(short_spec("ff", 1, noise_duration=4.0, sweep_duration=0.5), effects=["clipping:1.5"])
    assert max(s.clipped_fraction[1] for s in (session.noise, *session.sweeps)) > 0


def test_dc_offset_and_input_noise_levels():
    session = simulate_session(short_spec("ff", 1, noise_duration=4.0, sweep_duration=0.5),
                               effects=["dc-offset:0.01", "input-noise:10"])
    assert np.mean(session.noise.y) == pytest.approx(0.01, abs=2e-3)
    recorded = session.truth["effects"][1]["input_noise_rms"]
    difference = (session.sweeps[0].u - session.sweeps[1].u) / np.sqrt(2)
    assert np.std(difference) == pytest.approx(recorded, rel=0.05)


def test_clock_drift_shortens_the_delay_along_the_recording():
    session = simulate_session(short_spec("ff", 1, noise_duration=4.0, sweep_duration=0.5), effects=["clock-drift:200"])
    clean = simulate_session(short_spec("ff", 1, noise_duration=4.0, sweep_duration=0.5))
    assert np.max(np.abs(session.noise.y[:200] - clean.noise.y[:200])) < 1e-3
    assert np.max(np.abs(session.noise.y[-2000:] - clean.noise.y[-2000:])) > 1e-2
