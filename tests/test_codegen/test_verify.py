"""Verification of a host build (codegen.verify): the sweeps it reads and the figures it computes."""

import numpy as np
import pytest
from conftest_codegen import FS, log_sweep

from codegen.errors import CodegenError
from codegen.verify import load_sweeps, snr_db
from sysid.io.recordings import recording_from_arrays, write_wav16


class TestSnrDb:
    def test_known_ratio(self):
        reference = np.ones(100)
        assert snr_db(reference, reference + 0.1) == pytest.approx(20.0)

    def test_identical_is_infinite(self):
        assert snr_db(np.arange(5.0), np.arange(5.0)) == float("inf")


class TestLoadSweeps:
    def test_arrays_are_labelled_by_position(self):
        signals, labels = load_sweeps([np.zeros(4), [0.5, -0.5]])
        assert labels == ["sweep 1", "sweep 2"]
        np.testing.assert_array_equal(signals[1], [0.5, -0.5])

    def test_a_wav_file_gives_its_input_channel_and_name(self, tmp_path):
        u = 0.5 * log_sweep(0.05)
        write_wav16(tmp_path / "sweep1.wav", u, 0.5 * u, FS)
        signals, labels = load_sweeps([str(tmp_path / "sweep1.wav")], fs=FS)
        assert labels == ["sweep1.wav"]
        np.testing.assert_allclose(signals[0], u, atol=1.0 / 32768)

    def test_a_recording_at_another_rate_is_refused(self):
        u = 0.5 * log_sweep(0.05)
        recording = recording_from_arrays(u, u, FS, name="s.wav")
        with pytest.raises(CodegenError, match="recorded at 44100 Hz but the filter runs at 48000 Hz"):
            load_sweeps([recording], fs=48000.0)

    @pytest.mark.parametrize("sweep", [np.zeros(0), np.array([0.0, np.nan])])
    def test_empty_or_non_finite_arrays_are_refused(self, sweep):
        with pytest.raises(CodegenError, match="sweep 1 must be a non-empty array of finite samples"):
            load_sweeps([sweep])
