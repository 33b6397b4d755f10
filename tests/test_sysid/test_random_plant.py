"""Random helmet paths (sysid.random_plant): deterministic, stable, within the drawn ranges, no clipping."""

import json

import numpy as np
import pytest
import scipy.signal

from helmet_anc.cli import main
from sysid.core.errors import HelmetAncError
from sysid.core.model import Model
from sysid.random_plant import PLANT_RANGES, SAMPLE_RATES, _continuous_statespace, random_plant, random_session

SEEDS = range(40)


class TestRandomPlant:
    def test_same_seed_same_plant_and_paths_differ(self):
        a, b = random_plant(5), random_plant(5)
        assert a.description == b.description
        np.testing.assert_array_equal(a.model.A, b.model.A)
        np.testing.assert_array_equal(a.model.B, b.model.B)
        assert random_plant(5, "ff").description != a.description

    @pytest.mark.parametrize("seed", SEEDS)
    def test_stable_and_within_ranges(self, seed):
        rp = random_plant(seed)
        assert rp.model.stable and rp.model.delay == rp.delay
        assert rp.fs in SAMPLE_RATES and rp.model.fs == rp.fs
        assert PLANT_RANGES["modes"][0] <= len(rp.modes) <= PLANT_RANGES["modes"][1]
        for f0, q, a in rp.modes:
            assert PLANT_RANGES["f0_hz"][0] <= f0 <= PLANT_RANGES["f0_hz"][1]
            assert PLANT_RANGES["q"][0] <= q <= PLANT_RANGES["q"][1]
            assert a != 0
        assert PLANT_RANGES["delay"][0] <= rp.delay <= PLANT_RANGES["delay"][1]
        assert PLANT_RANGES["sensor_noise"][0] <= rp.sensor_noise <= PLANT_RANGES["sensor_noise"][1]
        assert rp.order == 2 * len(rp.modes) + len(rp.rolloff_hz) + (rp.highpass_hz is not None)
        # The drawn peak gain holds over 20 Hz-4 kHz.
        f = np.geomspace(20, 4000, 4000)
        assert np.max(np.abs(rp.model.frequency_response(f))) == pytest.approx(rp.peak_gain, rel=1e-6)

    @pytest.mark.parametrize("seed", [0, 7, 10, 28])
    def test_zoh_per_mode_equals_zoh_of_the_whole_system(self, seed):
        rp = random_plant(seed)
        ct = _continuous_statespace(rp.modes, rp.rolloff_hz, rp.highpass_hz)
        # The modal constants in rp.modes are already scaled, so the continuous system is the scaled one.
        discrete = scipy.signal.cont2discrete(ct, 1.0 / rp.fs, "zoh")[:4]
        f = np.geomspace(20, 0.45 * rp.fs, 300)
        expected = Model(path="fb", fs=rp.fs, A=discrete[0], B=discrete[1], C=discrete[2], D=discrete[3],
                         delay=rp.delay).frequency_response(f)
        got = rp.model.frequency_response(f)
        assert np.max(np.abs(got - expected)) < 1e-6 * np.max(np.abs(expected))

    def test_continuous_response_is_the_modal_sum(self):
        rp = random_plant(3)
        f = np.array([50.0, 300.0, 2000.0])
        s = 2j * np.pi * f
        expected = sum(a * (2 * np.pi * f0 / q) * s / (s**2 + (2 * np.pi * f0 / q) * s + (2 * np.pi * f0) ** 2)
                       for f0, q, a in rp.modes)
        if rp.highpass_hz is not None:
            expected = expected * s / (s + 2 * np.pi * rp.highpass_hz)
        for corner in rp.rolloff_hz:
            expected = expected * 2 * np.pi * corner / (s + 2 * np.pi * corner)
        A, B, C, D = _continuous_statespace(rp.modes, rp.rolloff_hz, rp.highpass_hz)
        got = np.array([(C @ np.linalg.solve(sk * np.eye(A.shape[0]) - A, B) + D)[0, 0] for sk in s])
        np.testing.assert_allclose(got, expected, rtol=1e-9)

    def test_family_has_non_minimum_phase_zeros_and_all_delays(self):
        plants = [random_plant(seed) for seed in SEEDS]
        assert any(np.any(np.abs(p.model.zeros()) > 1.0 + 1e-9) for p in plants)
        assert max(p.delay for p in plants) > 32 and min(p.delay for p in plants) < 16
        assert {p.fs for p in plants} == set(SAMPLE_RATES)

    @pytest.mark.parametrize("seed, path", [(-1, "fb"), (1.5, "fb"), ("3", "fb"), (True, "fb"), (2, "side")])
    def test_bad_values_rejected(self, seed, path):
        with pytest.raises(HelmetAncError, match="seed must be|path must be"):
            random_plant(seed, path)


class TestRandomSession:
    @pytest.mark.parametrize("seed", [0, 9, 17])
    def test_session_does_not_clip_and_holds_the_truth(self, seed):
        session = random_session(seed, noise_duration=4.0, sweep_duration=1.0, sweep_silence=0.2)
        rp = random_plant(seed)
        assert session.spec.fs == rp.fs and session.spec.output_noise == rp.sensor_noise
        for recording in (session.noise, *session.sweeps):
            assert np.max(np.abs(recording.y)) <= session.spec.peak_level + 0.01
            assert recording.clipped_fraction == (0.0, 0.0)
        truth_plant = Model.from_dict(json.loads(json.dumps(session.truth["plant"])))
        assert truth_plant.delay == rp.delay
        np.testing.assert_allclose(truth_plant.frequency_response([100.0, 1000.0]), rp.model.frequency_response([100.0, 1000.0]))
        assert session.truth["generator"]["description"] == rp.description

    def test_overrides_and_bad_settings(self):
        session = random_session(2, "ff", noise_duration=4.0, sweep_duration=0.5, output_noise=5e-4)
        assert session.spec.path == "ff" and session.spec.output_noise == 5e-4
        with pytest.raises(HelmetAncError, match="unknown session setting 'noise_seconds'"):
            random_session(2, noise_seconds=4.0)
        with pytest.raises(HelmetAncError, match="path and fs"):
            random_session(2, fs=8000.0)


class TestCommandLine:
    def test_simulate_random_writes_truth_with_delay(self, tmp_path, capsys):
        code = main(["simulate", str(tmp_path / "s"), "--plant", "random", "--seed", "12", "--path", "ff",
                     "--noise-seconds", "4", "--sweep-seconds", "0.5"])
        assert code == 0
        truth = json.loads((tmp_path / "s" / "truth.json").read_text())
        rp = random_plant(12, "ff")
        assert truth["plant"]["delay"] == rp.delay and truth["generator"]["seed"] == 12
        assert truth["spec"]["fs"] == rp.fs

    def test_negative_seed_is_one_line_and_writes_nothing(self, tmp_path, capsys):
        code = main(["simulate", str(tmp_path / "s"), "--plant", "random", "--seed", "-3"])
        _, err = capsys.readouterr()
        assert code == 2 and err.count("\n") == 1 and "--seed" in err
        assert not (tmp_path / "s").exists()
