"""The board's control path (firmware/anc_control.c) with a generated controller: per-sample
timing and latency, the closed loop on a simulated true plant (host C and the emulated
Cortex-M4 against the Python twin and the float64 design), the limiter, worst-case inputs,
and strict builds.

The controller is a board-sized one on the seed (Appendix A) plants (``control_cases.board_controller``;
a design takes minutes) for a latency of 2 samples, the per-sample path's (capture, compute, play). Cross compiler and emulator tests
skip with the reason when ``arm-none-eabi-gcc`` or ``qemu-system-arm`` is missing.
"""

from __future__ import annotations

import importlib.util
import subprocess
from pathlib import Path

import cffi
import numpy as np
import pytest
from control_cases import board_controller
from conftest_codegen import have
from repo import REPO

from anc.closed_loop import measured_attenuation, run_closed_loop
from anc.controller import Controller
from anc.disturbance import default_disturbance, synthesize
from anc.prediction import band_centres
from codegen.api import generate_controller_firmware
from codegen.build import HOST_CFLAGS
from codegen.control_loop import Limits, board_loop
from codegen.controller import plan_controller
from codegen.reference import to_q15
from sysid.core.model import Model
from sysid.core.plants import appendix_a_model

FIRMWARE = REPO / "firmware"
MAKEFILE = FIRMWARE / "Makefile"
STRICT = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Wconversion", "-Wpedantic", "-Wshadow", "-Wstrict-prototypes",
          "-Werror", "-ffp-contract=off"]
M4 = ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16", "-ffreestanding"]
QEMU = ["qemu-system-arm", "-M", "mps2-an386", "-nographic", "-monitor", "none", "-serial", "none",
        "-semihosting-config", "enable=on,target=native", "-kernel"]
CENTRES = np.array(band_centres())
CHECKED = (CENTRES >= 50.0) & (CENTRES <= 1000.0)
SECONDS = 1.0
needs_m4 = pytest.mark.skipif(not (have("arm-none-eabi-gcc") and have("qemu-system-arm")),
                              reason="arm-none-eabi-gcc or qemu-system-arm not installed "
                                     "(apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm)")


def _with_latency(controller: Controller, latency: int) -> Controller:
    data = controller.to_dict()
    data["latency_samples"] = latency
    return Controller.from_dict(data)


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    """The controller (latency 2), its generated folders (latency 2 and, for 4-frame blocks, 8),
    the true plants and 1 s of disturbance."""
    root = tmp_path_factory.mktemp("control")
    s_true, p_true = appendix_a_model("fb"), appendix_a_model("ff")
    controller = board_controller(s_true, p_true, 2)
    generate_controller_firmware(controller, root / "ctl2")
    generate_controller_firmware(_with_latency(controller, 8), root / "ctl8")
    x, u = synthesize(default_disturbance(controller.fs, p_true), int(SECONDS * controller.fs), controller.fs, 0)
    d = p_true.simulate(x) + u
    return {"root": root, "controller": controller, "plan": plan_controller(controller), "s_true": s_true,
            "x": x, "chin": to_q15(x), "d": d}


def _make(target, workdir, **variables):
    args = ["make", "-s", "-f", str(MAKEFILE), target] + [f"{k}={v}" for k, v in variables.items()]
    result = subprocess.run(args, cwd=workdir, capture_output=True, text=True, check=False, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    return result


def _write_inputs(work: Path, plant: Model, d: np.ndarray, chin: np.ndarray) -> None:
    work.mkdir(parents=True, exist_ok=True)
    header = np.concatenate(([plant.order, plant.delay], np.ravel(plant.A), np.ravel(plant.B), np.ravel(plant.C),
                             np.ravel(plant.D)))
    header.astype(np.float64).tofile(work / "plant.f64")
    np.asarray(d, np.float64).tofile(work / "d.f64")
    np.asarray(chin, np.int16).tofile(work / "chin.q15")


def _outputs(work: Path):
    status = np.fromfile(work / "status.u32", np.uint32)
    return np.fromfile(work / "ear.q15", np.int16), np.fromfile(work / "drive.q15", np.int16), status


def _executable(setup, variant: str) -> Path:
    """firmware/closed_loop.c built natively for the variant, once per module."""
    folder = setup["root"] / f"bin_{variant}"
    exe = folder / "build" / "closed_loop_host"
    if not exe.exists():
        folder.mkdir(exist_ok=True)
        _make("closed-loop-host", folder, CTL=setup["root"] / "ctl2",
              CONTROL="-DANC_CONTROL_F32" if variant == "float" else "")
    return exe


def _run_host(setup, name, plant, d, chin, variant="q15"):
    """Run firmware/closed_loop.c natively on the given plant and signals; returns (ear, drive, status)."""
    work = setup["root"] / name
    _write_inputs(work, plant, d, chin)
    result = subprocess.run([str(_executable(setup, variant))], cwd=work, capture_output=True, text=True,
                            check=False, timeout=120)
    assert result.returncode == 0 and "closed loop done" in result.stdout, result.stdout + result.stderr
    return _outputs(work)


def _assert_same_run(c_run, twin):
    ear, drive, status = c_run
    np.testing.assert_array_equal(ear, twin.ear)
    np.testing.assert_array_equal(drive, twin.drive)
    assert list(status) == [twin.muted, twin.trips, twin.muted_at, twin.frames, twin.model_saturations]


@pytest.fixture(scope="module")
def host_runs(setup):
    """The closed loop on the true FB plant: C on the host and the Python twin, per variant."""
    runs = {}
    for variant in ("q15", "float"):
        c_run = _run_host(setup, f"loop_{variant}", setup["s_true"], setup["d"], setup["chin"], variant)
        twin = board_loop(setup["plan"], setup["s_true"], setup["d"], setup["chin"], variant)
        runs[variant] = (c_run, twin)
    return runs


@pytest.mark.parametrize("variant", ["q15", "float"])
def test_host_closed_loop_equals_python_twin(host_runs, variant):
    """Every ear and drive word of the host C run equals the Python twin's (both variants)."""
    c_run, twin = host_runs[variant]
    _assert_same_run(c_run, twin)
    assert twin.trips == 0 and np.max(np.abs(twin.drive)) > 0


def test_attenuation_matches_python_and_float64_design(setup, host_runs):
    """Q15 and float runs against the float64 loop of the design (anc.closed_loop) on the same noise."""
    fs, d = setup["controller"].fs, setup["d"]
    design64 = np.array(measured_attenuation(d, run_closed_loop(setup["controller"], setup["s_true"], d, setup["x"]).e, fs))
    achieved = {}
    for variant, ((ear, _drive, _status), twin) in host_runs.items():
        achieved[variant] = np.array(measured_attenuation(d, ear / 32768.0, fs))
        twin_db = np.array(measured_attenuation(d, twin.ear / 32768.0, fs))
        tolerance = 0.0 if variant == "q15" else 0.1
        assert np.max(np.abs(achieved[variant] - twin_db)) <= tolerance
        gap = np.abs(achieved[variant] - design64)[CHECKED]
        assert np.max(gap) <= 1.0, f"{variant}: {np.max(gap):.2f} dB from the float64 design in a band 50 Hz-1 kHz"
    assert np.max(design64[CHECKED]) > 5.0  # the loop does attenuate: the comparison means something


@needs_m4
@pytest.mark.parametrize("variant", ["q15", "float"])
def test_qemu_closed_loop_equals_host(setup, host_runs, variant):
    """The Cortex-M4 ELF under QEMU (mps2-an386) runs the same loop to the same words as the host."""
    work = setup["root"] / f"m4_{variant}"
    _write_inputs(work, setup["s_true"], setup["d"], setup["chin"])
    _make("closed-loop-m4", work, CTL=setup["root"] / "ctl2",
          CONTROL="-DANC_CONTROL_F32" if variant == "float" else "")
    result = subprocess.run([*QEMU, str(work / "build" / "closed_loop_m4.elf")], cwd=work, capture_output=True,
                            text=True, check=False, timeout=300)
    assert result.returncode == 0 and "closed loop done" in result.stdout + result.stderr, result.stdout + result.stderr
    ear, drive, status = _outputs(work)
    (host_ear, host_drive, host_status), _twin = host_runs[variant]
    np.testing.assert_array_equal(ear, host_ear)
    np.testing.assert_array_equal(drive, host_drive)
    np.testing.assert_array_equal(status, host_status)


def test_limiter_mutes_destabilised_loop(setup):
    """The true speaker is wired the wrong way round (S_true = -S_model): the IMC loop gain is about
    -2 Q S and, without the limiter, d_hat and the drive grow to the rails. With it, the drive is
    muted (from the growth of d_hat, or from the rails within the stated number of frames) and the
    DAC plays zeros from ANC_PROCESSING_LATENCY frames after the trip on; the C equals the twin
    word for word."""
    s = setup["s_true"]
    flipped = Model(path="fb", fs=s.fs, A=s.A, B=s.B, C=-s.C, D=-s.D, delay=s.delay)
    limits = Limits()
    d, chin = setup["d"][:12000], setup["chin"][:12000]
    c_run = _run_host(setup, "unstable", flipped, d, chin)
    twin = board_loop(setup["plan"], flipped, d, chin, "q15", limits=limits)
    _assert_same_run(c_run, twin)
    unlimited = board_loop(setup["plan"], flipped, d, chin, "q15", limits=Limits(rail_samples=10**9, growth_windows=10**9))
    rails = np.nonzero((np.abs(unlimited.drive.astype(int)) >= 32767) | (np.abs(unlimited.d_hat.astype(int)) >= 32767))[0]
    assert rails.size, "the destabilised loop should reach the rails without the limiter"
    assert twin.trips == 1 and twin.muted in (1, 2)
    if twin.muted == 1:
        # The stated bound for rails touched in a fraction p of the frames (anc_control.h), the
        # frames counted from the first at a rail to the trip frame inclusive.
        frames = twin.muted_at - rails[0] + 1
        p = np.mean(np.isin(np.arange(rails[0], twin.muted_at + 1), rails))
        assert p > 1 / 9 and frames <= (8 * limits.rail_samples + 7) / (9 * p - 1)
    # The drive computed at the trip frame is already zero; it is played 2 frames later (B = 1).
    np.testing.assert_array_equal(twin.drive[: twin.muted_at + 2], unlimited.drive[: twin.muted_at + 2])
    assert np.all(twin.drive[twin.muted_at + 2:] == 0)


def test_limiter_rail_bound(setup):
    """A huge ear signal from frame 500 on puts d_hat at the rail in a fraction p of the frames (the
    drive's echo through S_model pulls it off now and then): the mute comes within the stated
    (8 ANC_LIMIT_RAIL_SAMPLES + 7) / (9 p - 1) frames, and exactly ANC_LIMIT_RAIL_SAMPLES when p = 1."""
    plan = setup["plan"]
    silent = Model(path="fb", fs=plan.controller.fs, A=np.zeros((0, 0)), B=np.zeros((0, 1)), C=np.zeros((1, 0)),
                   D=np.zeros((1, 1)))
    d = np.concatenate((np.zeros(500), np.full(1500, 2.0)))
    chin = np.zeros(d.size, np.int16)
    twin = board_loop(plan, silent, d, chin, "q15")
    _assert_same_run(_run_host(setup, "rails", silent, d, chin), twin)
    n = Limits().rail_samples
    assert twin.muted == 1 and np.max(np.abs(twin.drive.astype(int))) < 32767
    window = np.abs(twin.d_hat[500: twin.muted_at + 1].astype(int)) >= 32767
    p = np.mean(window)
    assert n <= twin.muted_at - 500 + 1 <= (8 * n + 7) / (9 * p - 1)
    if p == 1.0:
        assert twin.muted_at == 500 + n - 1


def test_stable_loop_never_trips_the_limiter(host_runs):
    for (_ear, _drive, status), _twin in host_runs.values():
        assert status[0] == 0 and status[1] == 0


# Per-sample timing: the codec DMA and interrupt, modelled frame by frame on a cffi build.
_TEST_C = """
#include "anc_control.h"
size_t test_size(void) { return sizeof(anc_control); }
int16_t *test_buffer(anc_control *ctl, unsigned half, int which)
{
    return which == 0 ? ctl->chin[half] : (which == 1 ? ctl->ear[half] : ctl->drive[half]);
}
unsigned test_block(void) { return ANC_CONTROL_BLOCK; }
unsigned test_latency(void) { return ANC_PROCESSING_LATENCY; }
unsigned test_controller_latency(void) { return CTL_LATENCY_SAMPLES; }
"""


def _control_module(root: Path, folder: Path, block: int):
    ffi = cffi.FFI()
    ffi.cdef("""
        typedef struct { ...; } anc_control;
        void anc_control_init(anc_control *ctl);
        void anc_control_dma_done(anc_control *ctl, unsigned half);
        size_t test_size(void);
        int16_t *test_buffer(anc_control *ctl, unsigned half, int which);
        unsigned test_block(void);
        unsigned test_latency(void);
        unsigned test_controller_latency(void);
    """)
    name = f"_anc_control_test_b{block}"
    sources = [str(FIRMWARE / "anc_control.c")] + [str(p) for p in sorted(folder.glob("ctl_*_filter.c"))]
    ffi.set_source(name, _TEST_C, sources=sources, include_dirs=[str(FIRMWARE), str(folder)],
                   extra_compile_args=[*HOST_CFLAGS, f"-DANC_CONTROL_BLOCK={block}u"])
    library = ffi.compile(tmpdir=str(root / name))
    spec = importlib.util.spec_from_file_location(name, library)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.lib, module.ffi


@pytest.mark.parametrize("block, folder", [(1, "ctl2"), (4, "ctl8")])
def test_every_drive_sample_played_once_at_the_stated_latency(setup, block, folder):
    """Frame by frame: the DAC plays drive[h][i] while the ADC captures into ear/chin[h][i]; after a
    half's last frame the codec interrupt runs anc_control_dma_done. Every computed drive sample is
    played exactly once, 2B frames after the capture it came from (never late, never twice), and a
    chin impulse first reaches the drive exactly CTL_LATENCY_SAMPLES frames later (W's own delay
    added), the latency the controller was designed for."""
    lib, ffi = _control_module(setup["root"], setup["root"] / folder, block)
    assert lib.test_block() == block and lib.test_latency() == 2 * block
    latency = lib.test_controller_latency()
    memory = ffi.new("char[]", lib.test_size())
    ctl = ffi.cast("anc_control *", memory)
    lib.anc_control_init(ctl)
    rng = np.random.default_rng(5)
    frames = 64 * block
    ear = to_q15(rng.uniform(-0.05, 0.05, frames))
    chin = to_q15(rng.uniform(-0.05, 0.05, frames))
    played = np.zeros(frames, np.int16)
    computed = []
    for k in range(frames):
        half, slot = (k // block) % 2, k % block
        played[k] = lib.test_buffer(ctl, half, 2)[slot]
        lib.test_buffer(ctl, half, 0)[slot] = int(chin[k])
        lib.test_buffer(ctl, half, 1)[slot] = int(ear[k])
        if slot == block - 1:
            lib.anc_control_dma_done(ctl, half)
            computed.append([lib.test_buffer(ctl, half, 2)[i] for i in range(block)])
    expected = np.concatenate((np.zeros(2 * block, np.int16), np.ravel(computed)[: frames - 2 * block]))
    np.testing.assert_array_equal(played, expected)
    assert np.count_nonzero(played) > frames // 2

    # Latency: a chin impulse alone (the drive it causes also reaches d_hat, but only later).
    lib.anc_control_init(ctl)
    w = setup["plan"].plans["ff"].realisation
    impulse = np.zeros(64)
    impulse[0] = 1.0
    from sysid.core import lti

    w_delay = int(np.argmax(np.abs(lti.simulate(w.A, w.B, w.C, w.D, impulse)) * 32767 >= 0.5)) + w.delay
    first = None
    for k in range(frames):
        half, slot = (k // block) % 2, k % block
        if lib.test_buffer(ctl, half, 2)[slot] != 0 and first is None:
            first = k
        lib.test_buffer(ctl, half, 0)[slot] = 32767 if k == block else 0
        lib.test_buffer(ctl, half, 1)[slot] = 0
        if slot == block - 1:
            lib.anc_control_dma_done(ctl, half)
    assert first == block + latency + w_delay


def _strict(compiler: str) -> list[str]:
    if not have(compiler):
        pytest.skip(f"{compiler} not installed: the strict build with it is not checked here")
    return [compiler, *STRICT, *(M4 if compiler.startswith("arm-") else [])]


@pytest.mark.parametrize("compiler", ["gcc", "clang", "arm-none-eabi-gcc"])
@pytest.mark.parametrize("options", [[], ["-DANC_CONTROL_F32"], ["-DANC_CONTROL_BLOCK=4u"]])
def test_control_path_compiles_strict(setup, tmp_path, compiler, options):
    cc = _strict(compiler)
    folder = setup["root"] / ("ctl8" if "-DANC_CONTROL_BLOCK=4u" in options else "ctl2")
    for source in ["anc_control.c", "closed_loop.c"]:
        result = subprocess.run([*cc, *options, "-I", str(FIRMWARE), "-I", str(folder), "-c", "-o",
                                 str(tmp_path / "out.o"), str(FIRMWARE / source)], capture_output=True, text=True,
                                check=False, timeout=120)
        assert result.returncode == 0, result.stderr
        if compiler.startswith("arm-") and source == "anc_control.c":
            # No heap, no libm, no libgcc helpers per sample: only the generated filters are called.
            undefined = subprocess.run(["arm-none-eabi-nm", "-u", str(tmp_path / "out.o")], capture_output=True,
                                       text=True, check=True, timeout=60).stdout.split()
            assert undefined and all(name.startswith("ctl_") for name in undefined[1::2]), undefined


def test_too_short_controller_latency_refused_at_compile_time(setup, tmp_path):
    """A controller designed for 2 samples cannot run on 4-frame blocks (8 samples of latency)."""
    cc = "gcc" if have("gcc") else "clang"
    result = subprocess.run([cc, *STRICT, "-DANC_CONTROL_BLOCK=4u", "-I", str(FIRMWARE), "-I",
                             str(setup["root"] / "ctl2"), "-c", "-o", str(tmp_path / "out.o"),
                             str(FIRMWARE / "anc_control.c")], capture_output=True, text=True, check=False, timeout=120)
    assert result.returncode != 0 and "latency_samples is below" in result.stderr


def test_closed_loop_clean_under_sanitizers(setup, tmp_path):
    """The control path and the harness under AddressSanitizer and UndefinedBehaviorSanitizer
    (gcc), on the miswired speaker: growth, rails, saturation and the mute all run."""
    if not have("gcc"):
        pytest.skip("gcc not installed")
    folder = setup["root"] / "ctl2"
    exe = tmp_path / "closed_loop_san"
    sources = [FIRMWARE / "closed_loop.c", FIRMWARE / "board_io_host.c", FIRMWARE / "anc_control.c",
               *sorted(folder.glob("ctl_*_filter.c"))]
    build = subprocess.run(["gcc", *STRICT, "-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-g",
                            "-I", str(FIRMWARE), "-I", str(folder), "-o", str(exe), *map(str, sources)],
                           capture_output=True, text=True, check=False, timeout=180)
    if build.returncode != 0 and "sanitizer" in build.stderr.lower() and "cannot find" in build.stderr.lower():
        pytest.skip("gcc's sanitizer runtime is not installed")
    assert build.returncode == 0, build.stderr
    s = setup["s_true"]
    flipped = Model(path="fb", fs=s.fs, A=s.A, B=s.B, C=-s.C, D=-s.D, delay=s.delay)
    _write_inputs(tmp_path, flipped, setup["d"][:8000], setup["chin"][:8000])
    result = subprocess.run([str(exe)], cwd=tmp_path, capture_output=True, text=True, check=False, timeout=120)
    assert result.returncode == 0 and result.stderr == "", result.stderr
    assert np.fromfile(tmp_path / "status.u32", np.uint32)[1] == 1  # the limiter tripped once


@pytest.mark.slow
def test_converter_latency_inside_the_identified_path(tmp_path):
    """Converters adding 3 samples (ANC_CONVERTER_LATENCY_SAMPLES): the true FB path and the model the
    controller is designed on both carry them (identification measures through the same converters),
    and the per-sample loop still equals its twin and the float64 design within 1 dB per band."""
    s_true = appendix_a_model("fb")
    s_true.delay = 3
    p_true = appendix_a_model("ff")
    controller = board_controller(s_true, p_true, 2)
    generate_controller_firmware(controller, tmp_path / "ctl2")
    fs = controller.fs
    x, u = synthesize(default_disturbance(fs, p_true), int(SECONDS * fs), fs, 1)
    d = p_true.simulate(x) + u
    setup = {"root": tmp_path}
    c_run = _run_host(setup, "loop", s_true, d, to_q15(x))
    twin = board_loop(plan_controller(controller), s_true, d, to_q15(x), "q15")
    _assert_same_run(c_run, twin)
    achieved = np.array(measured_attenuation(d, twin.ear / 32768.0, fs))
    design64 = np.array(measured_attenuation(d, run_closed_loop(controller, s_true, d, x).e, fs))
    assert np.max(np.abs(achieved - design64)[CHECKED]) <= 1.0
