"""The cmsis target against the cmsisdsp package (CMSIS-DSP's kernels compiled for the host)."""

import re

import numpy as np
import pytest
from conftest_codegen import appendix_a_model, model_sweeps, random_stable_model

from codegen.api import generate_firmware
from codegen.build import CmsisPackageFilter
from codegen.cmsis import (KERNELS, cmsis_q15_reference, design_cmsis, df2t_f32_reference, q15_kernel, q31_kernel,
                           q31x64_kernel)
from codegen.plan import plan_firmware
from codegen.realise import realise
from codegen.reference import float64_reference, from_q15, to_q15
from codegen.sections import design_cascade
from codegen.verify import snr_db

dsp = pytest.importorskip("cmsisdsp", reason="the cmsisdsp package is not installed")


def _package_q31(tables, x):
    stages = len(tables.q31_coefficients)
    instance = dsp.arm_biquad_casd_df1_inst_q31()
    state = np.zeros(4 * stages, np.int32)
    dsp.arm_biquad_cascade_df1_init_q31(instance, stages, np.array(tables.q31_coefficients, np.int32).ravel(),
                                        state, tables.post_shift)
    half = x.size // 2
    return np.concatenate((dsp.arm_biquad_cascade_df1_q31(instance, x[:half]),
                           dsp.arm_biquad_cascade_df1_q31(instance, x[half:])))


@pytest.mark.parametrize("path", ["fb", "ff"])
def test_q31_kernel_bit_exact_with_package(path):
    model = appendix_a_model(path)
    tables = design_cmsis(design_cascade(realise(model)), 0)
    for sweep in model_sweeps(model, seconds=0.15):
        x = to_q15(sweep).astype(np.int32) * 65536
        np.testing.assert_array_equal(q31_kernel(tables, x), _package_q31(tables, x))


def test_q31_kernel_bit_exact_when_accumulator_wraps():
    # Random coefficients and full-scale input make the 64-bit sum and the output wrap.
    rng = np.random.default_rng(5)
    model = random_stable_model(9, 4, radius_max=0.99)
    tables = design_cmsis(design_cascade(realise(model), headroom_db=0.0), 0)
    x = rng.integers(-(2**31), 2**31 - 1, 2000).astype(np.int32)
    np.testing.assert_array_equal(q31_kernel(tables, x), _package_q31(tables, x))


def _package_wide(tables, x):
    stages = len(tables.q31_coefficients)
    instance = dsp.arm_biquad_cas_df1_32x64_ins_q31()
    dsp.arm_biquad_cas_df1_32x64_init_q31(instance, stages, np.array(tables.q31_coefficients, np.int32).ravel(),
                                          np.zeros(4 * stages, np.int64), tables.post_shift)
    half = x.size // 3
    return np.concatenate((dsp.arm_biquad_cas_df1_32x64_q31(instance, x[:half]),
                           dsp.arm_biquad_cas_df1_32x64_q31(instance, x[half:])))


def _package_q15(tables, x):
    stages = len(tables.q15_coefficients)
    instance = dsp.arm_biquad_casd_df1_inst_q15()
    rows = np.array([(r[0], 0, *r[1:]) for r in tables.q15_coefficients], np.int16).ravel()
    dsp.arm_biquad_cascade_df1_init_q15(instance, stages, rows, np.zeros(4 * stages, np.int16), tables.q15_post_shift)
    return dsp.arm_biquad_cascade_df1_q15(instance, x)


@pytest.mark.parametrize("path", ["fb", "ff"])
def test_q31x64_kernel_bit_exact_with_package(path):
    model = appendix_a_model(path)
    tables = design_cmsis(design_cascade(realise(model)), 0, kernel="q31x64")
    x = to_q15(model_sweeps(model, seconds=0.1)[1]).astype(np.int32) * 65536
    np.testing.assert_array_equal(q31x64_kernel(tables, x), _package_wide(tables, x))


def test_q15_kernel_bit_exact_with_package_including_saturation():
    rng = np.random.default_rng(8)
    model = random_stable_model(4, 4, radius_max=0.95)
    tables = design_cmsis(design_cascade(realise(model), headroom_db=0.0), 0, kernel="q15")
    x = rng.integers(-32768, 32767, 3000).astype(np.int16)
    y = q15_kernel(tables, x)
    np.testing.assert_array_equal(y, _package_q15(tables, x))
    assert np.any(np.abs(y.astype(int)) == 32767) or np.any(y == -32768)


@pytest.mark.parametrize("kernel", KERNELS)
def test_package_filter_matches_reference_for_each_kernel(kernel):
    model = appendix_a_model("ff")
    tables = design_cmsis(design_cascade(realise(model)), 2, kernel=kernel)
    q = to_q15(model_sweeps(model, seconds=0.05)[0])
    package = CmsisPackageFilter(tables)
    out = np.concatenate((package.process_q15(q[:700]), package.process_q15(q[700:])))
    np.testing.assert_array_equal(out, cmsis_q15_reference(tables, q))


def test_generated_tables_and_package_verification(tmp_path):
    model = appendix_a_model("ff")
    sweeps = model_sweeps(model, seconds=0.15)
    manifest = generate_firmware(model, tmp_path / "cmsis", target="cmsis", min_snr=40.0, sweeps=sweeps)
    source = (tmp_path / "cmsis" / "ff_filter.c").read_text()
    plan = plan_firmware(model, target="cmsis", min_snr=40.0)
    assert plan.cmsis.kernel == "q31" and manifest.data["formats"]["cmsis"]["kernel"] == "q31"
    table = re.search(r"ff_q31_coefficients\[\d+\] = \{(.*?)\};", source, re.DOTALL).group(1)
    numbers = [int(v) for v in re.findall(r"\(q31_t\)(-?\d+)", table)]
    assert numbers == [v for row in plan.cmsis.q31_coefficients for v in row]
    assert "arm_biquad_cascade_df1_init_q31" in source and f"{plan.cmsis.post_shift});" in source
    for row in manifest.verification["sweeps"]:
        assert row["q15"]["max_lsb_difference"] == 0
        assert row["float"]["snr_vs_float64_db"] > 75


def test_package_filter_matches_reference_with_delay():
    model = appendix_a_model("ff")
    tables = design_cmsis(design_cascade(realise(model)), 4)
    assert tables.kernel == "q31"
    q = to_q15(model_sweeps(model, seconds=0.1)[0])
    package = CmsisPackageFilter(tables)
    out = np.concatenate((package.process_q15(q[:1000]), package.process_q15(q[1000:])))
    np.testing.assert_array_equal(out, cmsis_q15_reference(tables, q))
    xf = from_q15(q).astype(np.float32)
    np.testing.assert_allclose(package.process_f32(xf), df2t_f32_reference(tables, xf), atol=1e-5)
    assert snr_db(float64_reference(realise(model), from_q15(q))[:-4], from_q15(out)[4:]) > 60
