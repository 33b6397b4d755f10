"""The generated C against its Python references: 0 LSB (Q15) and bit-exact float32.

Also the promise that the fixed-point code saturates instead of wrapping, on
full-scale and worst-case (sign of the time-reversed impulse response) inputs.
"""

import numpy as np
import pytest
from conftest_codegen import appendix_a_model, model_sweeps, random_stable_model
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from codegen.api import generate_firmware
from codegen.build import build_host
from codegen.plan import plan_firmware
from codegen.reference import FixedFilter, fixed_reference, float32_reference, float64_reference, from_q15, to_q15
from sysid.core.model import Model


def _build(model, outdir, **options):
    manifest = generate_firmware(model, outdir, **options)
    name = manifest.name
    host = build_host(name, (outdir / f"{name}_filter.h").read_text(), (outdir / f"{name}_filter.c").read_text())
    plan = plan_firmware(model, **{k: v for k, v in options.items() if k not in ("name", "sweeps")})
    return plan, host


def _in_blocks(run, x, sizes=(1, 31, 64, 7)):
    """Feed x in blocks of varying length (the state must carry over)."""
    out, start, k = [], 0, 0
    while start < x.size:
        stop = min(x.size, start + sizes[k % len(sizes)] * 37)
        out.append(run(x[start:stop]))
        start, k = stop, k + 1
    return np.concatenate(out)


def _worst_case_input(model, length=6000):
    impulse = np.zeros(length)
    impulse[0] = 1.0
    h = model.simulate(impulse)
    return np.where(h[::-1] >= 0, 32767, -32768).astype(np.int16)


@pytest.fixture(scope="module", params=["fb", "ff"])
def appendix_build(request, tmp_path_factory):
    model = appendix_a_model(request.param)
    return model, *_build(model, tmp_path_factory.mktemp(request.param) / "gen")


class TestAppendixModels:
    def test_sweeps_zero_lsb_and_float_bit_exact(self, appendix_build):
        model, plan, host = appendix_build
        for sweep in model_sweeps(model, seconds=0.2):
            q = to_q15(sweep)
            host.reset("q15")
            np.testing.assert_array_equal(_in_blocks(host.process_q15, q), fixed_reference(plan.fixed, q))
            xf = sweep.astype(np.float32)
            host.reset("f32")
            np.testing.assert_array_equal(_in_blocks(host.process_f32, xf), float32_reference(plan.floating, xf))

    def test_full_scale_noise(self, appendix_build):
        _model, plan, host = appendix_build
        rng = np.random.default_rng(7)
        q = np.where(rng.random(4000) < 0.5, 32767, -32768).astype(np.int16)
        host.reset("q15")
        np.testing.assert_array_equal(host.process_q15(q), fixed_reference(plan.fixed, q))

    def test_worst_case_input_saturates_never_wraps(self, appendix_build):
        model, plan, host = appendix_build
        q = _worst_case_input(model)
        host.reset("q15")
        c_out = host.process_q15(q)
        np.testing.assert_array_equal(c_out, fixed_reference(plan.fixed, q))
        exact = float64_reference(plan.realisation, from_q15(q))
        # The last sample collects sum|h|: beyond full scale it must sit on the rail of its sign
        # (a wrap-around would land on the other side).
        if abs(exact[-1]) > 1.0:
            assert c_out[-1] == (32767 if exact[-1] > 0 else -32768)
        else:
            assert abs(from_q15(c_out[-1:])[0] - exact[-1]) < 1e-3

    def test_worst_case_input_at_output_full_scale_is_linear(self, appendix_build):
        # Scaled so the exact output just reaches full scale, no node may overflow:
        # the C output then follows the float64 model closely everywhere.
        model, plan, host = appendix_build
        worst = _worst_case_input(model).astype(float) / 32768
        exact = float64_reference(plan.realisation, worst)
        q = to_q15(worst * 0.98 / np.max(np.abs(exact)))
        host.reset("q15")
        c_out = host.process_q15(q)
        np.testing.assert_array_equal(c_out, fixed_reference(plan.fixed, q))
        exact = float64_reference(plan.realisation, from_q15(q))
        assert np.max(np.abs(from_q15(c_out) - exact)) < 1e-3


def test_short_blocks_and_odd_tails(appendix_build):
    """Blocks of 1, 2, 3 and 33 samples (pairs, odd tails, a chunk boundary) in C and in FixedFilter."""
    model, plan, host = appendix_build
    x = to_q15(model_sweeps(model, seconds=0.05)[0])
    expected = fixed_reference(plan.fixed, x)
    host.reset("q15")
    stepper = FixedFilter(plan.fixed)
    c_out, py_out, start, k = [], [], 0, 0
    while start < x.size:
        stop = min(x.size, start + (1, 2, 3, 33)[k % 4])
        c_out.append(host.process_q15(x[start:stop]))
        py_out.append(stepper.process(x[start:stop]))
        start, k = stop, k + 1
    assert np.array_equal(np.concatenate(c_out), expected)
    assert np.array_equal(np.concatenate(py_out), expected)


def test_delay_and_input_polynomial(tmp_path):
    model = appendix_a_model("ff")
    model.delay = 5
    model.input_nonlinearity = [0.9, 0.25, -0.4]
    plan, host = _build(model, tmp_path / "gen", name="ff_poly")
    rng = np.random.default_rng(11)
    q = to_q15(rng.uniform(-1, 1, 3000))
    np.testing.assert_array_equal(_in_blocks(host.process_q15, q), fixed_reference(plan.fixed, q))
    xf = from_q15(q).astype(np.float32)
    np.testing.assert_array_equal(_in_blocks(host.process_f32, xf), float32_reference(plan.floating, xf))
    exact = model.simulate(from_q15(q))
    assert np.all(np.abs(from_q15(fixed_reference(plan.fixed, q)) - exact) < 1e-3)
    assert np.all(exact[:5] == 0) and np.all(fixed_reference(plan.fixed, q)[:5] == 0)


@settings(max_examples=4, deadline=None, database=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 10_000), order=st.integers(1, 6), delay=st.integers(0, 3))
def test_random_stable_models(tmp_path, seed, order, delay):
    model = random_stable_model(seed, order, delay=delay)
    plan, host = _build(model, tmp_path / f"gen{seed}_{order}_{delay}", name="rnd", min_snr=0.0)
    rng = np.random.default_rng(seed)
    q = to_q15(rng.uniform(-1, 1, 1500) * rng.choice([0.01, 0.3, 1.0]))
    np.testing.assert_array_equal(host.process_q15(q), fixed_reference(plan.fixed, q))
    worst = _worst_case_input(model, 1500)
    host.reset("q15")
    np.testing.assert_array_equal(host.process_q15(worst), fixed_reference(plan.fixed, worst))
    xf = from_q15(q).astype(np.float32)
    np.testing.assert_array_equal(host.process_f32(xf), float32_reference(plan.floating, xf))


def test_static_gain_model(tmp_path):
    model = Model(path="ff", fs=44100.0, A=np.zeros((0, 0)), B=np.zeros((0, 1)), C=np.zeros((1, 0)), D=[[0.5]])
    plan, host = _build(model, tmp_path / "gen")
    q = np.array([0, 1000, -32768, 32767, 3], dtype=np.int16)
    np.testing.assert_array_equal(host.process_q15(q), fixed_reference(plan.fixed, q))
    np.testing.assert_array_equal(host.process_q15(q), np.floor(q / 2 + 0.5).astype(np.int16))
