"""Tests of codegen.fixedpoint, codegen.float32 and codegen.noise (design and prediction)."""

import numpy as np
import pytest
from conftest_codegen import appendix_a_model, model_sweeps

import scipy.signal

from codegen.errors import PrecisionError
from codegen.fixedpoint import COEFFICIENT_SUM_LIMIT, FEEDBACK_GUARD, _fits, design_fixed, polynomial_exponent
from codegen.float32 import design_float32
from codegen.noise import predict_fixed, predict_float32
from codegen.plan import plan_firmware
from codegen.realise import realise
from codegen.reference import (fixed_input, fixed_reference, fixed_section, float64_reference, from_q15,
                               q31_to_q15_output, to_q15)
from codegen.sections import Cascade, cascade_response, design_cascade, peak_grid, scale_sections
from sysid.core.sections import unit_section


@pytest.fixture(scope="module", params=["fb", "ff"])
def cascade(request):
    return request.param, design_cascade(realise(appendix_a_model(request.param)))


class TestFixedDesign:
    def test_accumulator_bound(self, cascade):
        _, c = cascade
        design = design_fixed(c, 0)
        for s in design.sections:
            assert max(abs(v) for v in (*s.b, *s.a)) <= 2**31 - 1
            # Feedback sum shifted down by d, plus the numerator sum, with states up to 2^31 and the
            # residue below 2^32: the int64 accumulator cannot overflow.
            bound = (sum(abs(v) for v in s.a) / 2**s.feedback_shift + sum(abs(v) for v in s.b)) * 2**31 + 2**32
            assert bound < 2**63
            assert sum(abs(v) for v in s.a) / 2**s.feedback_shift + sum(abs(v) for v in s.b) <= COEFFICIENT_SUM_LIMIT

    def test_guard_is_the_smallest_that_fits(self, cascade):
        _, c = cascade
        for s, exact in zip(design_fixed(c, 0).sections, c.sections):
            assert s.guard == 0 or not _fits(exact.b, (-exact.a[1], -exact.a[2]), s.guard - 1, 0)
            # The feedback gets its own bits only where the numerator pushed the guard up.
            assert s.feedback_shift == 0 or s.guard > FEEDBACK_GUARD

    def test_quantised_response_close(self, cascade):
        _, c = cascade
        design = design_fixed(c, 0)
        w = peak_grid([p for s in c.sections for p in s.poles])
        exact = cascade_response(c.sections, w)
        approx = cascade_response([s.realised() for s in design.sections], w)
        assert np.max(np.abs(approx - exact) / np.abs(exact)) < 1e-5

    def test_polynomial_exponent(self):
        assert polynomial_exponent([0.5, 0.2]) == 0
        assert polynomial_exponent([1.0]) == 1
        assert polynomial_exponent([1.5, -1.0]) == 2


class TestPrediction:
    def test_predicted_q15_floor_and_measured_snr(self, cascade):
        path, c = cascade
        model = appendix_a_model(path)
        design = design_fixed(c, 0)
        prediction = predict_fixed(c, design, model.fs)
        # The Q15 output quantiser alone gives 6.02 * 16 + 1.76 = 98.1 dB for a full-scale sine.
        assert prediction.roundoff_snr_db == pytest.approx(98.1, abs=0.5)
        for sweep in model_sweeps(model, seconds=0.2, peak=0.9):
            q = to_q15(sweep)
            exact = float64_reference(realise(model), from_q15(q))
            error = from_q15(fixed_reference(design, q)) - exact
            ideal = from_q15(to_q15(exact)) - exact
            # Internal round-off is far below the output quantiser: within 0.5 dB of ideal rounding.
            assert 10 * np.log10(np.sum(error**2) / np.sum(ideal**2)) < 0.5

    def test_error_feedback_beats_rounding_inside(self, cascade):
        path, c = cascade
        fs = appendix_a_model(path).fs
        efb = predict_fixed(c, design_fixed(c, 0, quantiser="efb"), fs).roundoff_power
        rnd = predict_fixed(c, design_fixed(c, 0, quantiser="round"), fs).roundoff_power
        q15 = 2.0**-30 / 12
        assert efb - q15 < rnd - q15

    def test_float32_prediction_meets_target(self, cascade):
        path, c = cascade
        assert predict_float32(c, design_float32(c, 0), appendix_a_model(path).fs).snr_db > 90


class TestRefusal:
    def test_min_snr_refusal_names_reason(self):
        with pytest.raises(PrecisionError, match=r"q15 variant refused: predicted SNR 98\.\d dB is below --min-snr 120 dB; limited by round-off"):
            plan_firmware(appendix_a_model("ff"), variant="q15", min_snr=120.0)

    @pytest.mark.parametrize("path, min_snr, kernel", [("fb", 80.0, "q31x64"), ("ff", 80.0, "q31"),
                                                        ("fb", 10.0, "q31"), ("ff", 10.0, "q15")])
    def test_cheapest_cmsis_kernel_meeting_request(self, path, min_snr, kernel):
        plan = plan_firmware(appendix_a_model(path), variant="q15", target="cmsis", min_snr=min_snr)
        assert plan.cmsis.kernel == kernel
        assert plan.predictions["q15"].snr_db >= min_snr
        if path == "fb":
            # Q15 coefficients put the pole at 0.99991 onto the unit circle.
            assert plan.kernel_predictions["q15"].snr_db == float("-inf")

    def test_cmsis_refusal_names_best_kernel(self):
        with pytest.raises(PrecisionError, match=r"best CMSIS kernel arm_biquad_cas_df1_32x64_q31\) refused"):
            plan_firmware(appendix_a_model("fb"), variant="q15", target="cmsis", min_snr=110.0)


def _tail_after_burst(design):
    """|output| over the last 20000 samples of 200000 zeros that follow a 2000-sample noise burst."""
    rng = np.random.default_rng(1)
    x = np.concatenate((to_q15(rng.uniform(-0.5, 0.5, 2000)), np.zeros(200_000, np.int16)))
    return np.abs(fixed_reference(design, x)[-20_000:].astype(int))


def test_round_quantiser_refused_for_recursive_sections():
    """Rounding leaves a +-2 LSB zero-input limit cycle on the FB model: plan_firmware refuses it with the reason."""
    realisation = realise(appendix_a_model("fb"))
    cascade = design_cascade(realisation)
    assert _tail_after_burst(design_fixed(cascade, realisation.delay, None, "round")).max() >= 1  # the defect
    with pytest.raises(PrecisionError, match="limit cycle"):
        plan_firmware(appendix_a_model("fb"), quantiser="round")


@pytest.mark.parametrize("path", ["fb", "ff"])
def test_error_feedback_decays_to_exact_zero(path):
    plan = plan_firmware(appendix_a_model(path))
    assert plan.fixed.quantiser == "efb"
    assert _tail_after_burst(plan.fixed).max() == 0


def test_round_off_of_poles_near_one_is_as_predicted_from_rest():
    """A feed-forward filter's shape (resonances at 4 and 10 Hz with poles at radius 0.9995, then a gain of 30
    at 3 kHz): the Q15 error against float64 over 0.1 s of noise from rest is within 3 dB of the predicted round-off.
    With the error-feedback residues started at 0 instead of their mean, the first sample's half-step, rung by the
    resonances unshaped, made it 5-7 times the prediction (the seed pair's W: 718 times over a 0.4 s sweep)."""
    fs = 48000.0
    unit = [unit_section([p, np.conj(p)], [-1.0, 0.9])
            for p in (0.9995 * np.exp(2j * np.pi * f / fs) for f in (4.0, 10.0))]
    top = 0.95 * np.exp(2j * np.pi * 3000.0 / fs)
    unit.append(unit_section([top, np.conj(top)], [0.95, 0.95]))
    peak = np.max(np.abs(cascade_response(unit, peak_grid([p for s in unit for p in s.poles]))))
    sections, gains = scale_sections(unit, 30.0 / peak)
    cascade = Cascade(sections=tuple(sections), scaling="linf", headroom_db=6.0, node_gains=tuple(gains),
                      realisation_error=0.0)
    design = design_fixed(cascade, 0)
    prediction = predict_fixed(cascade, design, fs)
    x = to_q15(0.25 / 30.0 * np.random.default_rng(0).standard_normal(4800))
    exact = scipy.signal.sosfilt(np.array([list(s.b) + list(s.a) for s in sections]), from_q15(x))
    expected = prediction.roundoff_power + np.mean(exact**2) * 10 ** (-prediction.coefficient_snr_db / 10)
    measured = np.mean((from_q15(fixed_reference(design, x)) - exact) ** 2)
    assert 0.5 < measured / expected < 2.0
    # The defect: residues from 0.
    signal = fixed_input(design, x)
    for section in design.sections:
        signal, _ = fixed_section(section, signal, design.quantiser, (0, 0, 0, 0, 0))
    assert np.mean((from_q15(q31_to_q15_output(signal)) - exact) ** 2) / expected > 4.0
