"""The generated filters on the Cortex-M4 (QEMU mps2-an386) against the host, and the board runtime.

Needs ``arm-none-eabi-gcc`` (with newlib headers) and ``qemu-system-arm``; the
tests that use them skip with the reason when they are missing.
"""

import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest_codegen import CMSIS_DECLARATIONS, appendix_a_model, have, model_sweeps
from repo import REPO

from codegen.api import generate_firmware
from codegen.build import HOST_CFLAGS
from codegen.plan import plan_firmware
from codegen.reference import fixed_reference, float32_reference, from_q15, to_q15

FIRMWARE = REPO / "firmware"
MAKEFILE = FIRMWARE / "Makefile"
needs_cross = pytest.mark.skipif(not have("arm-none-eabi-gcc"),
                                 reason="arm-none-eabi-gcc not installed (apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi)")
needs_qemu = pytest.mark.skipif(not have("qemu-system-arm"), reason="qemu-system-arm not installed (apt-get install qemu-system-arm)")


def _make(target, workdir, **variables):
    args = ["make", "-s", "-f", str(MAKEFILE), target] + [f"{k}={v}" for k, v in variables.items()]
    result = subprocess.run(args, cwd=workdir, capture_output=True, text=True, check=False, timeout=180)
    assert result.returncode == 0, result.stdout + result.stderr
    return result


@pytest.fixture(scope="module", params=["fb", "ff"])
def harness_run(request, tmp_path_factory):
    """Generated filter, its input files, and the outputs of the host and QEMU runs."""
    path = request.param
    model = appendix_a_model(path)
    root = tmp_path_factory.mktemp(f"fw_{path}")
    generate_firmware(model, root / "gen")
    sweep = np.concatenate(model_sweeps(model, seconds=0.1))
    q = to_q15(sweep)
    xf = from_q15(q).astype(np.float32)
    outputs = {}
    for where in ("host", "m4"):
        work = root / where
        work.mkdir()
        q.tofile(work / "in_q15.raw")
        xf.tofile(work / "in_f32.raw")
        outputs[where] = work
    return model, root, q, xf, outputs


def _outputs(work):
    return np.fromfile(work / "out_q15.raw", np.int16), np.fromfile(work / "out_f32.raw", np.float32)


def test_host_harness_matches_reference(harness_run):
    model, root, q, xf, outputs = harness_run
    _make("host", outputs["host"], GEN=root / "gen", NAME=model.path)
    result = subprocess.run([str(outputs["host"] / "build" / "harness_host")], cwd=outputs["host"],
                            capture_output=True, text=True, check=False, timeout=60)
    assert result.returncode == 0, result.stdout
    y_q15, y_f32 = _outputs(outputs["host"])
    plan = plan_firmware(model)
    np.testing.assert_array_equal(y_q15, fixed_reference(plan.fixed, q))
    np.testing.assert_array_equal(y_f32, float32_reference(plan.floating, xf))


@needs_cross
@needs_qemu
def test_qemu_output_equals_host_output(harness_run):
    model, root, q, _xf, outputs = harness_run
    if not (outputs["host"] / "out_q15.raw").exists():
        _make("host", outputs["host"], GEN=root / "gen", NAME=model.path)
        subprocess.run([str(outputs["host"] / "build" / "harness_host")], cwd=outputs["host"], check=True, timeout=60)
    _make("m4", outputs["m4"], GEN=root / "gen", NAME=model.path)
    result = subprocess.run(["qemu-system-arm", "-M", "mps2-an386", "-nographic", "-monitor", "none", "-serial", "none",
                             "-semihosting-config", "enable=on,target=native",
                             "-kernel", str(outputs["m4"] / "build" / "harness_m4.elf")],
                            cwd=outputs["m4"], capture_output=True, text=True, check=False, timeout=120)
    assert result.returncode == 0 and "harness done" in result.stdout + result.stderr, result.stdout + result.stderr
    m4_q15, m4_f32 = _outputs(outputs["m4"])
    host_q15, host_f32 = _outputs(outputs["host"])
    assert m4_q15.size == q.size
    np.testing.assert_array_equal(m4_q15, host_q15)  # 0 LSB
    np.testing.assert_array_equal(m4_f32.view(np.uint32), host_f32.view(np.uint32))


@needs_cross
def test_cross_compile_clean_and_sized(tmp_path):
    generate_firmware(appendix_a_model("fb"), tmp_path / "gen")
    result = _make("size", tmp_path, GEN=tmp_path / "gen", NAME="fb")
    text = result.stdout.split()
    sizes = dict(zip(text[:6], text[6:12]))
    assert 0 < int(sizes["text"]) < 8192 and int(sizes["data"]) == 0 and int(sizes["bss"]) == 0
    # No undefined symbols: no heap, no libm, no libgcc helpers in the filter.
    undefined = subprocess.run(["arm-none-eabi-nm", "-u", str(tmp_path / "build" / "filter_m4.o")],
                               capture_output=True, text=True, check=True, timeout=60).stdout.split()
    assert undefined == []


@needs_cross
def test_cross_compile_with_delay_and_polynomial(tmp_path):
    model = appendix_a_model("ff")
    model.delay, model.input_nonlinearity = 7, [1.0, 0.1, -0.05]
    generate_firmware(model, tmp_path / "gen", name="ff_nl")
    _make("size", tmp_path, GEN=tmp_path / "gen", NAME="ff_nl")


@pytest.fixture(scope="module")
def runtime_sources(tmp_path_factory):
    root = tmp_path_factory.mktemp("runtime")
    generate_firmware(appendix_a_model("fb"), root / "fb", variant="q15")
    generate_firmware(appendix_a_model("ff"), root / "ff", variant="q15")
    return root


@needs_cross
def test_runtime_cross_compiles(runtime_sources):
    _make("runtime-m4", runtime_sources, FB=runtime_sources / "fb", FF=runtime_sources / "ff")
    assert (runtime_sources / "build" / "anc_runtime_m4.o").stat().st_size > 0




@pytest.mark.parametrize("compiler", ["gcc", "arm-none-eabi-gcc"])
@pytest.mark.parametrize("path, min_snr, kernel", [("ff", 10.0, "q15"), ("ff", 80.0, "q31"), ("fb", 80.0, "q31x64")])
def test_cmsis_target_compiles_clean(tmp_path, compiler, path, min_snr, kernel):
    if not have(compiler):
        pytest.skip(f"{compiler} not installed")
    model = appendix_a_model(path)
    model.delay = 3
    manifest = generate_firmware(model, tmp_path / "gen", target="cmsis", min_snr=min_snr)
    assert manifest.data["formats"]["cmsis"]["kernel"] == kernel
    (tmp_path / "gen" / "arm_math.h").write_text(CMSIS_DECLARATIONS)
    flags = list(HOST_CFLAGS)
    if compiler != "gcc":
        flags += ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"]
    result = subprocess.run([compiler, *flags, "-c", "-o", "filter.o", f"{path}_filter.c"], cwd=tmp_path / "gen",
                            capture_output=True, text=True, check=False, timeout=120)
    assert result.returncode == 0, result.stderr
