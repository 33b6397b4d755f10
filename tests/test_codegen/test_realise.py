"""Tests of codegen.realise: truncation, re-discretisation, refusals (the balancing: tests/test_sysid/core/test_lti.py)."""

import numpy as np
import pytest
from conftest_codegen import appendix_a_model, random_stable_model

from codegen.errors import UnstableModelError
from codegen.realise import realise, rediscretise
from sysid.core import lti
from sysid.core.model import Model


class TestTruncation:
    def test_truncation_error_within_enns_bound(self):
        m = random_stable_model(3, 8, radius_max=0.99)
        full = realise(m)
        cut = realise(m, order=4)
        assert cut.A.shape == (4, 4) and cut.truncated_from == 8
        z = np.exp(1j * np.linspace(0, np.pi, 4000))
        error = np.abs(lti.frequency_response(cut.A, cut.B, cut.C, cut.D, z)
                       - lti.frequency_response(full.A, full.B, full.C, full.D, z))
        assert error.max() <= cut.truncation_bound * (1 + 1e-6)
        assert cut.truncation_bound == pytest.approx(2 * full.hankel_singular_values[4:].sum())


class TestRediscretise:
    def test_round_trip_is_identity(self):
        m = appendix_a_model("ff")
        A, B = rediscretise(m.A, m.B, 44100.0, 44100.0)
        np.testing.assert_allclose(A, m.A, atol=1e-10)
        np.testing.assert_allclose(B, m.B, atol=1e-10)

    def test_pole_mapping_and_low_frequency_response(self):
        m = appendix_a_model("ff")
        r = realise(m, fs=48000.0)
        # z = exp(s T): pole moduli follow |z'| = |z|^(T'/T).
        expected = np.sort(np.abs(m.poles()) ** (44100.0 / 48000.0))
        np.testing.assert_allclose(np.sort(np.abs(np.linalg.eigvals(r.A))), expected, rtol=1e-9)
        f = np.array([50.0, 200.0])
        h_model = m.frequency_response(f)
        h_board = lti.frequency_response(r.A, r.B, r.C, r.D, np.exp(2j * np.pi * f / 48000.0))
        # A zero-order hold is exact at DC and close far below the Nyquist frequency.
        np.testing.assert_allclose(np.abs(h_board), np.abs(h_model), rtol=2e-2)

    def test_delay_rounded_and_error_stated(self):
        m = appendix_a_model("fb")
        m.delay = 7
        r = realise(m, fs=16000.0)
        assert r.delay == round(7 * 16000 / 44100)
        assert r.delay_error_s == pytest.approx(r.delay / 16000 - 7 / 44100)


def test_unstable_model_refused():
    m = Model(path="fb", fs=44100.0, A=[[1.01]], B=[[1.0]], C=[[1.0]], D=[[0.0]])
    with pytest.raises(UnstableModelError, match="unstable"):
        realise(m)
    r = realise(m, allow_unstable=True)
    assert r.A[0, 0] == pytest.approx(1.01)


def test_pole_on_unit_circle_refused_even_when_unstable_allowed():
    """A pole at z = 1 has no finite gain to scale by (the reference used to crash with NaN)."""
    from codegen.plan import plan_firmware

    model = Model(path="fb", fs=44100.0, A=np.diag([1.0, 0.5]), B=np.ones((2, 1)), C=np.array([[0.01, 0.2]]),
                  D=np.zeros((1, 1)))
    with pytest.raises(UnstableModelError, match="unit circle"):
        plan_firmware(model, allow_unstable=True)
    model.A = np.diag([1.001, 0.5])  # strictly outside: still generated when allowed
    assert plan_firmware(model, allow_unstable=True, min_snr=0.0).fixed is not None
