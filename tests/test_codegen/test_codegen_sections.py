"""Tests of codegen.sections: pairing, ordering, relative degree, scaling."""

import numpy as np
import pytest
import scipy.signal
from conftest_codegen import appendix_a_model, random_stable_model

from codegen.realise import realise
from codegen.sections import cascade_response, design_cascade, pair_sections, peak_grid
from sysid.core import lti
from sysid.core.model import Model


def _impulse(sections, n=64):
    x = np.zeros(n)
    x[0] = 1.0
    sos = np.array([list(s.b) + list(s.a) for s in sections])
    return scipy.signal.sosfilt(sos, x)


class TestRelativeDegree:
    @pytest.mark.parametrize("path", ["fb", "ff"])
    def test_impulse_response_matches_state_space(self, path):
        m = appendix_a_model(path)
        cascade = design_cascade(realise(m))
        impulse = np.zeros(200)
        impulse[0] = 1.0
        expected = lti.simulate(m.A, m.B, m.C, m.D, impulse)
        np.testing.assert_allclose(_impulse(cascade.sections, 200), expected, atol=1e-9 * np.abs(expected).max())

    def test_strictly_proper_delay_survives(self):
        # Relative degree 2: h(0) = h(1) = 0. scipy's zpk2sos pads zeros at the origin
        # and advances the response by one sample per missing zero.
        m = Model(path="ff", fs=44100.0, A=[[0.9, 0.0], [1.0, 0.5]], B=[[1.0], [0.0]], C=[[0.0, 1.0]], D=[[0.0]])
        cascade = design_cascade(realise(m))
        h = _impulse(cascade.sections, 10)
        assert h[0] == 0.0 and h[1] == 0.0 and h[2] != 0.0
        zeros, poles = lti.invariant_zeros(m.A, m.B, m.C, m.D), np.linalg.eigvals(m.A)
        padded = scipy.signal.zpk2sos(zeros, poles, 1.0)
        advanced = scipy.signal.sosfilt(padded, np.eye(1, 10)[0])
        assert advanced[0] != 0.0  # what the naive route would have produced

    def test_model_with_feedthrough(self):
        m = random_stable_model(5, 4, strictly_proper=False)
        cascade = design_cascade(realise(m))
        expected = lti.simulate(m.A, m.B, m.C, m.D, np.eye(1, 100)[0])
        np.testing.assert_allclose(_impulse(cascade.sections, 100), expected, atol=1e-9 * np.abs(expected).max())


class TestPairingAndOrdering:
    def test_poles_closest_to_circle_last(self):
        cascade = design_cascade(realise(appendix_a_model("fb")))
        radii = [s.radius for s in cascade.sections]
        assert radii == sorted(radii)
        assert radii[-1] == pytest.approx(0.99991362, abs=1e-7)

    def test_nearest_zero_pairing(self):
        poles = [0.99, 0.5 + 0.5j, 0.5 - 0.5j]
        zeros = [1.01, 0.45 + 0.55j, 0.45 - 0.55j]
        groups = pair_sections(np.array(poles), np.array(zeros))
        for pole_set, zero_set in groups:
            if len(pole_set) == 1:
                assert zero_set == (1.01 + 0j,)
            else:
                assert {complex(np.round(z, 6)) for z in zero_set} == {0.45 + 0.55j, 0.45 - 0.55j}

    def test_complex_zero_pairs_kept_together(self):
        poles = np.array([0.9, 0.8, 0.7, 0.6])
        zeros = np.array([0.3 + 0.2j, 0.3 - 0.2j, 0.1 + 0.1j, 0.1 - 0.1j])
        for _, zero_set in pair_sections(poles, zeros):
            assert len(zero_set) == 2 and zero_set[0] == np.conj(zero_set[1])


class TestScaling:
    @pytest.mark.parametrize("path", ["fb", "ff"])
    def test_partial_cascades_at_headroom(self, path):
        cascade = design_cascade(realise(appendix_a_model(path)), headroom_db=6.0)
        w = peak_grid([p for s in cascade.sections for p in s.poles], points=16384)
        for k in range(len(cascade.sections) - 1):
            peak = np.max(np.abs(cascade_response(cascade.sections, w, k + 1)))
            assert 20 * np.log10(peak) == pytest.approx(-6.0, abs=0.01)

    def test_l1_scaling_bounds_worst_case(self):
        cascade = design_cascade(realise(appendix_a_model("ff")), scaling="l1", headroom_db=0.0)
        for k in range(len(cascade.sections) - 1):
            h = _impulse(cascade.sections[: k + 1], 20000)
            assert np.sum(np.abs(h)) == pytest.approx(1.0, rel=1e-3)
