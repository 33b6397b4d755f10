"""sysid.estimation.output_error_data: the band's DFT bins of a block of a noise recording."""

import numpy as np
import pytest

from sysid.core.errors import IdentificationError
from sysid.estimation.output_error_data import block_data
from sysid.io.recordings import Recording


def test_a_tone_on_a_bin_is_one_bin_of_the_block():
    # 1000 samples at 10 kHz: bins every 10 Hz. A cosine at 500 Hz (bin 50) of amplitude 0.2 through a gain of 3.
    fs, n = 10000.0, 1000
    u = 0.2 * np.cos(2 * np.pi * 500.0 * np.arange(n) / fs) + 0.7  # the channel mean is removed
    data = block_data(Recording(u, 3.0 * u, fs, "tone"), band=(400.0, 600.0), max_seconds=None)
    assert (data.length, data.fs, data.z.size) == (n, fs, 21)
    np.testing.assert_allclose(data.z, np.exp(2j * np.pi * np.arange(40, 61) / n), rtol=1e-12)
    expected = np.zeros(21, complex)
    expected[10] = 0.2 * n / 2
    np.testing.assert_allclose(data.U, expected, atol=1e-9)
    np.testing.assert_allclose(data.Y, 3.0 * expected, atol=1e-9)


def test_the_block_is_at_most_max_seconds_long():
    u = np.random.default_rng(0).standard_normal(30000)
    assert block_data(Recording(u, u, 10000.0, "noise"), max_seconds=2.0).length == 20000


def test_a_recording_too_short_for_a_block_is_refused():
    with pytest.raises(IdentificationError, match="tiny: too short for output-error refinement"):
        block_data(Recording(np.ones(15), np.ones(15), 10000.0, "tiny"))
