"""The generated C, the runtime, the harness and the start-up code compile warning-free under
strict flags with every compiler found (gcc, clang, arm-none-eabi-gcc), and the host harness
runs clean under AddressSanitizer and UndefinedBehaviorSanitizer."""

import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest_codegen import CMSIS_DECLARATIONS, appendix_a_model, have
from repo import REPO

from codegen.api import generate_firmware
from codegen.reference import to_q15

FIRMWARE = REPO / "firmware"
STRICT = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Wconversion", "-Wpedantic", "-Wshadow", "-Wstrict-prototypes",
          "-Werror", "-ffp-contract=off"]
M4 = ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16", "-ffreestanding"]
COMPILERS = ["gcc", "clang", "arm-none-eabi-gcc"]
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-g"]


def _compiler(name):
    if not have(name):
        pytest.skip(f"{name} not installed: the strict build with it is not checked here")
    return [name, *STRICT, *(M4 if name.startswith("arm-") else [])]


def _run(args, cwd):
    result = subprocess.run(args, cwd=cwd, capture_output=True, text=True, check=False, timeout=180)
    assert result.returncode == 0, " ".join(map(str, args)) + "\n" + result.stdout + result.stderr
    return result


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    """Generated filters: generic (both variants, one with delay and polynomial) and the three cmsis kernels."""
    root = tmp_path_factory.mktemp("strict")
    generate_firmware(appendix_a_model("fb"), root / "fb")
    generate_firmware(appendix_a_model("ff"), root / "ff")
    nl = appendix_a_model("ff")
    nl.delay, nl.input_nonlinearity = 5, [1.0, 0.1, -0.05]
    generate_firmware(nl, root / "ff_nl", name="ff_nl")
    for path, min_snr, kernel in (("ff", 10.0, "q15"), ("ff", 80.0, "q31"), ("fb", 80.0, "q31x64")):
        model = appendix_a_model(path)
        model.delay = 3
        manifest = generate_firmware(model, root / f"cmsis_{kernel}", name=f"c_{kernel}", target="cmsis",
                                     min_snr=min_snr)
        assert manifest.data["formats"]["cmsis"]["kernel"] == kernel
        (root / f"cmsis_{kernel}" / "arm_math.h").write_text(CMSIS_DECLARATIONS)
    return root


@pytest.mark.parametrize("compiler", COMPILERS)
def test_generated_filters_compile_strict(sources, tmp_path, compiler):
    cc = _compiler(compiler)
    for folder, name in (("fb", "fb"), ("ff", "ff"), ("ff_nl", "ff_nl"), ("cmsis_q15", "c_q15"),
                         ("cmsis_q31", "c_q31"), ("cmsis_q31x64", "c_q31x64")):
        _run([*cc, "-I", str(sources / folder), "-c", "-o", str(tmp_path / f"{name}.o"),
              str(sources / folder / f"{name}_filter.c")], tmp_path)


@pytest.mark.parametrize("compiler", COMPILERS)
def test_runtime_compiles_strict(sources, tmp_path, compiler):
    cc = _compiler(compiler)
    _run([*cc, "-I", str(FIRMWARE), "-I", str(sources / "fb"), "-I", str(sources / "ff"), "-c", "-o",
          str(tmp_path / "anc_runtime.o"), str(FIRMWARE / "anc_runtime.c")], tmp_path)


@pytest.mark.parametrize("compiler", COMPILERS)
def test_harness_and_startup_build_strict(sources, tmp_path, compiler):
    cc = _compiler(compiler)
    defines = ["-DFILTER_NAME=fb", '-DFILTER_HEADER="fb_filter.h"', "-DHARNESS_Q15", "-DHARNESS_F32",
               "-I", str(FIRMWARE), "-I", str(sources / "fb")]
    common = [str(FIRMWARE / "harness.c"), str(sources / "fb" / "fb_filter.c")]
    if compiler.startswith("arm-"):
        _run([*cc, *defines, "-nostdlib", "-nostartfiles", "-T", str(FIRMWARE / "mps2_an386.ld"), "-o",
              str(tmp_path / "harness.elf"), *common, str(FIRMWARE / "board_io_semihost.c"),
              str(FIRMWARE / "startup_mps2_an386.c"), "-lgcc"], tmp_path)
    else:
        _run([*cc, *defines, "-o", str(tmp_path / "harness"), *common, str(FIRMWARE / "board_io_host.c")], tmp_path)


def _sanitizers_link(compiler, folder):
    """Whether the compiler's ASan/UBSan runtime libraries are installed (clang's ship separately)."""
    probe = folder / "probe.c"
    probe.write_text("int main(void) { return 0; }\n")
    return subprocess.run([compiler, *SANITIZE, "-o", str(folder / "probe"), str(probe)], capture_output=True,
                          check=False, timeout=60).returncode == 0


def _host_harness(sources, tmp_path, compiler, extra=()):
    cc = _compiler(compiler)
    exe = tmp_path / f"harness_{compiler}"
    _run([*cc, *extra, "-DFILTER_NAME=fb", '-DFILTER_HEADER="fb_filter.h"', "-DHARNESS_Q15", "-DHARNESS_F32",
          "-I", str(FIRMWARE), "-I", str(sources / "fb"), "-o", str(exe), str(FIRMWARE / "harness.c"),
          str(FIRMWARE / "board_io_host.c"), str(sources / "fb" / "fb_filter.c")], tmp_path)
    return exe


@pytest.mark.parametrize("compiler", ["gcc", "clang"])
def test_harness_clean_under_sanitizers(sources, tmp_path, compiler):
    """Full-scale noise, a full-scale step and the rails alternating, through the Q15 and float filters."""
    _compiler(compiler)
    if not _sanitizers_link(compiler, tmp_path):
        pytest.skip(f"{compiler}'s sanitizer runtime is not installed (clang: apt-get install libclang-rt-dev)")
    exe = _host_harness(sources, tmp_path, compiler, SANITIZE)
    rng = np.random.default_rng(12)
    x = np.concatenate((rng.uniform(-1, 1, 4000), np.ones(2000), -np.ones(2000), np.tile([1.0, -1.0], 1000)))
    to_q15(x).tofile(tmp_path / "in_q15.raw")
    x.astype(np.float32).tofile(tmp_path / "in_f32.raw")
    result = _run([str(exe)], tmp_path)
    assert "harness done" in result.stdout and result.stderr == ""
    assert np.fromfile(tmp_path / "out_q15.raw", np.int16).size == x.size


def test_harness_refuses_input_beyond_its_limit(sources, tmp_path):
    """262145 samples: refused with the limit in the message, no output written (never truncated)."""
    exe = _host_harness(sources, tmp_path, "gcc" if have("gcc") else "clang")
    np.zeros(262145, np.int16).tofile(tmp_path / "in_q15.raw")
    np.zeros(10, np.float32).tofile(tmp_path / "in_f32.raw")
    result = subprocess.run([str(exe)], cwd=tmp_path, capture_output=True, text=True, check=False, timeout=60)
    assert result.returncode != 0
    assert "in_q15.raw: longer than 262144 samples" in result.stdout
    assert not (tmp_path / "out_q15.raw").exists()
