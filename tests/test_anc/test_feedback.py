"""The feedback bound and the design within 1.5 dB of it, closed loop on the TRUE plants.

Designed on models identified from short sessions, the noise given as a recording with ANC off
(``control_cases.recording_with_anc_off``), judged on the true plants against a fresh noise
realisation (``control_cases.judge``). The closed-loop checks are slow (identification, the bound with its
four relaxations, the design and the judge: the design alone 8 CPU-s for the seed pair); the default run checks
the bound's pieces, the seed's bound on its true path and a capped design.
"""

from __future__ import annotations

import numpy as np
import pytest
from control_cases import RANDOM_FB_SEEDS, identified, judge, random_pair, recording_with_anc_off, seed_pair

from anc.closed_loop import closed_loop_poles
from anc.controller import Controller
from anc.disc_program import DiscProgram, solve_disc_program
from anc.disturbance import from_recording
from anc.feedback import design_feedback
from anc.feedback_bound import LIMIT_BANDS, amplification_limit, feedback_bound
from anc.outer_factor import outer_factor
from anc.prediction import band_centres
from anc.rational_basis import RationalBasis, basis_poles
from anc.uncertainty import Uncertainty, model_uncertainty
from sysid.core.plants import appendix_a_model
from sysid.core.response import frequency_response

CENTRES = np.array(band_centres())
JUDGED = (CENTRES >= 50.0) & (CENTRES <= 1000.0)
LATENCY = 1


class TestDiscProgram:
    def test_a_binding_disc_holds_the_minimum_on_its_edge(self):
        # min |c - 2|^2 over |c| <= 1 (real c): c = 1; a second, slack disc changes nothing.
        program = DiscProgram(np.eye(1), np.array([-2.0]), np.array([[1.0 + 0j], [0.5j]]),
                              np.array([0.0 + 0j, 0.0 + 0j]), np.array([1.0, 10.0]))
        c = solve_disc_program(program)
        assert c[0] == pytest.approx(1.0, abs=1e-5)

    def test_a_start_outside_a_disc_is_refused(self):
        program = DiscProgram(np.eye(1), np.zeros(1), np.array([[1.0 + 0j]]), np.array([2.0 + 0j]), np.array([1.0]))
        with pytest.raises(ValueError, match="strictly inside"):
            solve_disc_program(program)


class TestRationalBasis:
    def test_the_realisation_is_the_functions_sum(self):
        fs = 48000.0
        basis = RationalBasis.of(basis_poles(fs, 12, 5.0, 5000.0, 4))
        c = np.random.default_rng(3).standard_normal(basis.size)
        f = np.geomspace(1.0, 20000.0, 50)
        A, B, C, D = basis.statespace(c)
        realised = frequency_response(A, B, C, D, np.exp(2j * np.pi * f / fs))
        np.testing.assert_allclose(realised.reshape(-1), basis.responses(f, fs) @ c, rtol=1e-8, atol=1e-10)

    def test_the_functions_are_orthonormal_on_the_circle(self):
        basis = RationalBasis.of(basis_poles(8000.0, 8, 50.0, 2000.0, 4))
        f = np.arange(8192) * 8000.0 / 8192
        phi = basis.responses(f, 8000.0)
        gram = phi.conj().T @ phi / f.size
        np.testing.assert_allclose(gram, np.eye(basis.size), atol=1e-6)


def test_the_outer_factor_has_the_paths_magnitude_and_a_stable_inverse():
    model = appendix_a_model("fb")
    outer = outer_factor(model)
    f = np.geomspace(30.0, 0.4 * model.fs, 200)
    np.testing.assert_allclose(np.abs(outer.response(f)), np.abs(model.frequency_response(f)), rtol=1e-6)
    A = outer.inverse_statespace()[0]
    assert np.max(np.abs(np.linalg.eigvals(A))) < 1.0


def test_the_amplification_limit_is_per_band_and_refuses_zero():
    per_band = np.full(len(LIMIT_BANDS), 6.0)
    per_band[[i for i, (c, _, _) in enumerate(LIMIT_BANDS) if 300.0 <= c <= 3400.0]] = 1.0
    limits = amplification_limit([5.0, 100.0, 1000.0, 20000.0], per_band)
    np.testing.assert_allclose(limits, [6.0, 6.0, 1.0, 6.0])
    with pytest.raises(ValueError, match="positive"):
        amplification_limit([100.0], 0.0)


def _designed(pair, name):
    s_model, _ = identified(name)
    disturbance = from_recording(recording_with_anc_off(pair.p), s_model.fs)
    return s_model, design_feedback(s_model, disturbance, LATENCY, model_uncertainty(s_model))


def _check_closed_loop(pair, name):
    """The issue's checks for the feedback part: within 1.5 dB of the bound, stable on the true path,
    achieved within 2 dB of predicted per band, no band louder than the stated limit."""
    s_model, design = _designed(pair, name)
    bound = design.bound
    assert np.all(design.amplification_db <= design.amplification_limit_db + 1e-6), \
        f"the model's loop exceeds the stated limit: {design.amplification_db - design.amplification_limit_db}"
    assert bound.limits and len(bound.limits) == len(bound.bands_hz)
    controller = Controller(s_model.fs, s_model, None, design.filter, LATENCY, list(CENTRES),
                            {part: list(design.predicted_db) for part in ("ff", "fb", "both")})
    poles = closed_loop_poles(controller, pair.s)
    assert np.max(np.abs(poles), initial=0.0) < 1.0, f"unstable on the true path: {np.max(np.abs(poles)):.6f}"
    achieved = judge(controller, pair).per_band["fb"]
    predicted = design.predicted_db
    worst = int(np.argmax(np.abs(achieved - predicted) * JUDGED))
    assert abs(achieved[worst] - predicted[worst]) <= 2.0, \
        f"{CENTRES[worst]:g} Hz: achieved {achieved[worst]:.1f} dB, predicted {predicted[worst]:.1f} dB"
    limit = float(np.max(design.amplification_limit_db))
    assert np.min(achieved[JUDGED]) >= -limit, f"a band {-np.min(achieved[JUDGED]):.1f} dB louder"
    mean = float(np.mean(achieved[JUDGED]))
    assert mean >= bound.mean_db - 1.5, f"achieved {mean:.1f} dB against the bound {bound.mean_db:.1f} dB"
    return bound, mean


@pytest.mark.slow
def test_seed_pair_reaches_the_bound_within_1_5_db():
    bound, mean = _check_closed_loop(seed_pair(), "seed")
    # The issue's figure for the seed (latency 1, 6 dB peak, 5 % uncertainty) is 5.7 dB; the identified
    # model's own uncertainty band is wider at the band edges, so the bound may lie somewhat below it.
    assert bound.mean_db >= 3.0


@pytest.mark.slow
@pytest.mark.parametrize("fb_seed", RANDOM_FB_SEEDS)
def test_random_paths_reach_the_bound_within_1_5_db(fb_seed):
    _check_closed_loop(random_pair(fb_seed), f"random {fb_seed}")


def _five_percent(fs: float) -> Uncertainty:
    """Issue 26's stated robustness: a 5 % relative error at every frequency."""
    return Uncertainty(np.array([1e-3, fs / 2.0]), np.array([0.05, 0.05]), (0.0, fs / 2.0), "5 % everywhere")


def test_the_seed_bound_on_the_true_path_is_the_issues_reference():
    # Issue 26: 5.7 dB for the seed's FB path at latency 1, 5 % uncertainty and a 6 dB peak (its own convex
    # design); this program found 6.0 dB. The noise differs in realisation, so within 1 dB.
    pair = seed_pair()
    disturbance = from_recording(recording_with_anc_off(pair.p), pair.s.fs)
    bound = feedback_bound(pair.s, disturbance, LATENCY, _five_percent(pair.s.fs), explain=False)
    assert abs(bound.mean_db - 5.7) <= 1.0, f"{bound.mean_db:.2f} dB"


def test_a_capped_feedback_filter_keeps_the_cap_and_the_stated_bounds():
    pair = seed_pair()
    disturbance = from_recording(recording_with_anc_off(pair.p), pair.s.fs)
    cap = 40
    design = design_feedback(pair.s, disturbance, LATENCY, _five_percent(pair.s.fs), explain=False, max_order=cap)
    assert design.filter.order <= cap
    assert np.max(np.abs(np.linalg.eigvals(design.filter.A))) < 1.0
    assert np.all(design.amplification_db <= design.amplification_limit_db + 1e-6)
    assert design.reduction["capped"] and design.reduction["cap_cost_db"] >= 0.0
    assert any("capped at" in note and "dB below the full filter" in note for note in design.notes)
    with pytest.raises(ValueError, match="max_order"):
        design_feedback(pair.s, disturbance, LATENCY, _five_percent(pair.s.fs), max_order=2)
