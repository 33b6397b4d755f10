"""The board runtime (firmware/anc_runtime.c) on the host: DMA ping-pong timing, the
interrupt/main-loop sharing, and the observer/predictor signal flow."""

import importlib.util
from pathlib import Path

import cffi
import numpy as np
import pytest
from conftest_codegen import appendix_a_model
from repo import REPO

from codegen.api import generate_firmware
from codegen.build import HOST_CFLAGS
from codegen.plan import plan_firmware
from codegen.reference import fixed_reference, to_q15

FIRMWARE = REPO / "firmware"
BLOCK = 32

# Test control laws: 'negate' cancels the FF prediction; 'tag' writes (call number + 1) * 64 + i,
# so every speaker sample names the anc_process_block call that computed it.
_TEST_C = """
#include "anc_runtime.h"
static uint32_t calls;
static void negate(void *context, const int16_t *d_hat, const int16_t *ff_pred, int16_t *speaker, size_t n)
{
    size_t i;
    (void)context; (void)d_hat;
    for (i = 0; i < n; ++i) {
        speaker[i] = (int16_t)((ff_pred[i] == -32768) ? 32767 : -ff_pred[i]);
    }
}
static void tag(void *context, const int16_t *d_hat, const int16_t *ff_pred, int16_t *speaker, size_t n)
{
    size_t i;
    (void)context; (void)d_hat; (void)ff_pred;
    ++calls;
    for (i = 0; i < n; ++i) {
        speaker[i] = (int16_t)(calls * 64u + i);
    }
}
static int16_t dc_level;
static void dc(void *context, const int16_t *d_hat, const int16_t *ff_pred, int16_t *speaker, size_t n)
{
    size_t i;
    (void)context; (void)d_hat; (void)ff_pred;
    for (i = 0; i < n; ++i) {
        speaker[i] = dc_level;
    }
}
void test_setup(anc_runtime *rt, int law)
{
    calls = 0u;
    anc_init(rt, law == 0 ? negate : (law == 1 ? tag : dc), NULL);
}
void test_set_dc(int16_t level) { dc_level = level; }
int test_headroom(void) { return FB_DC_HEADROOM_LSB; }
uint32_t test_saturations(const anc_runtime *rt) { return rt->model_saturations; }
int16_t *test_buffer(anc_runtime *rt, unsigned half, int which)
{
    return which == 0 ? rt->chin[half] : (which == 1 ? rt->ear[half] : rt->speaker[half]);
}
int16_t *test_signal(anc_runtime *rt, int which) { return which == 0 ? rt->d_hat : rt->ff_pred; }
size_t test_size(void) { return sizeof(anc_runtime); }
"""


@pytest.fixture(scope="module")
def runtime(tmp_path_factory):
    """(lib, ffi) of the runtime built with the Appendix A FB and FF filters (Q15)."""
    root = tmp_path_factory.mktemp("runtime")
    generate_firmware(appendix_a_model("fb"), root / "fb", variant="q15")
    generate_firmware(appendix_a_model("ff"), root / "ff", variant="q15")
    ffi = cffi.FFI()
    ffi.cdef("""
        typedef struct { ...; } anc_runtime;
        void test_setup(anc_runtime *rt, int law);
        void test_set_dc(int16_t level);
        int test_headroom(void);
        uint32_t test_saturations(const anc_runtime *rt);
        void anc_dma_block_done(anc_runtime *rt, unsigned half);
        int anc_service(anc_runtime *rt);
        int16_t *test_buffer(anc_runtime *rt, unsigned half, int which);
        int16_t *test_signal(anc_runtime *rt, int which);
        size_t test_size(void);
    """)
    ffi.set_source("_anc_runtime_test", _TEST_C,
                   sources=[str(FIRMWARE / "anc_runtime.c"), str(root / "fb" / "fb_filter.c"),
                            str(root / "ff" / "ff_filter.c")],
                   include_dirs=[str(FIRMWARE), str(root / "fb"), str(root / "ff")], extra_compile_args=list(HOST_CFLAGS))
    library = ffi.compile(tmpdir=str(root))
    spec = importlib.util.spec_from_file_location("_anc_runtime_test", library)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.lib, module.ffi


def _new(runtime, law):
    lib, ffi = runtime
    memory = ffi.new("char[]", lib.test_size())
    rt = ffi.cast("anc_runtime *", memory)
    lib.test_setup(rt, law)
    return memory, rt


def _read(ffi, pointer, n=BLOCK):
    return np.frombuffer(ffi.buffer(pointer, 2 * n), np.int16).copy()


@pytest.mark.parametrize("service_at", [0, 5, BLOCK - 1])
def test_dma_ping_pong_plays_every_sample_once_in_order(runtime, service_at):
    """Sample-level model of the codec DMA: during block k it plays speaker[k % 2] sample by sample;
    the main loop services the half completed at the end of block k - 1 after ``service_at`` samples
    of block k have gone out. Every computed sample must be played exactly once, two blocks after
    the capture it was computed from, never torn by a write into the half being played."""
    lib, ffi = runtime
    _memory, rt = _new(runtime, law=1)
    blocks = 12
    played = np.zeros((blocks, BLOCK), np.int64)
    for k in range(blocks):
        half = k % 2
        speaker = lib.test_buffer(rt, half, 2)
        for n in range(BLOCK):
            if n == service_at:
                while lib.anc_service(rt):
                    pass
            played[k, n] = speaker[n]
        lib.anc_dma_block_done(rt, half)
    # The block captured at k is processed by call k + 1 (1-based) and played at block k + 2.
    expected = np.zeros((blocks, BLOCK), np.int64)
    for k in range(2, blocks):
        expected[k] = (k - 1) * 64 + np.arange(BLOCK)
    np.testing.assert_array_equal(played, expected)


def _writes(ffi, memory, action):
    """Byte offsets of the runtime struct that ``action()`` changes."""
    before = bytes(ffi.buffer(memory))
    action()
    after = bytes(ffi.buffer(memory))
    return {i for i, (a, b) in enumerate(zip(before, after)) if a != b}


def test_interrupt_and_main_loop_write_disjoint_words(runtime):
    """No read-modify-write shared between the DMA interrupt and the main loop: the bytes the
    interrupt side writes (including an overrun) and those anc_service writes never overlap."""
    lib, ffi = runtime
    memory, rt = _new(runtime, law=1)
    interrupt, main = set(), set()
    for k in range(6):
        half = k % 2
        interrupt |= _writes(ffi, memory, lambda: lib.anc_dma_block_done(rt, half))
        if k == 3:  # the main loop is late: the same half completes again (an overrun)
            interrupt |= _writes(ffi, memory, lambda: lib.anc_dma_block_done(rt, half))
        main |= _writes(ffi, memory, lambda: lib.anc_service(rt))
        main |= _writes(ffi, memory, lambda: lib.anc_service(rt))
    assert interrupt and main
    assert not interrupt & main


def test_observer_and_predictor(runtime):
    """d_hat = ear - G_fb * played and ff_pred = G_ff * chin, block by block, double-buffered."""
    lib, ffi = runtime
    _memory, rt = _new(runtime, law=0)
    rng = np.random.default_rng(3)
    blocks = 20
    chin = to_q15(rng.uniform(-0.3, 0.3, blocks * BLOCK))
    ear = to_q15(rng.uniform(-0.3, 0.3, blocks * BLOCK))
    d_hat, ff_pred, speaker = [], [], []
    for k in range(blocks):
        half = k % 2
        ffi.memmove(lib.test_buffer(rt, half, 0), chin[k * BLOCK:(k + 1) * BLOCK].tobytes(), 2 * BLOCK)
        ffi.memmove(lib.test_buffer(rt, half, 1), ear[k * BLOCK:(k + 1) * BLOCK].tobytes(), 2 * BLOCK)
        lib.anc_dma_block_done(rt, half)
        assert lib.anc_service(rt) == 1 and lib.anc_service(rt) == 0
        d_hat.append(_read(ffi, lib.test_signal(rt, 0)))
        ff_pred.append(_read(ffi, lib.test_signal(rt, 1)))
        speaker.append(_read(ffi, lib.test_buffer(rt, half, 2)))

    fb_plan, ff_plan = plan_firmware(appendix_a_model("fb"), variant="q15"), plan_firmware(appendix_a_model("ff"), variant="q15")
    expected_ff = fixed_reference(ff_plan.fixed, chin)
    np.testing.assert_array_equal(np.concatenate(ff_pred), expected_ff)
    expected_speaker = np.where(expected_ff == -32768, 32767, -expected_ff.astype(np.int32)).astype(np.int16)
    np.testing.assert_array_equal(np.concatenate(speaker), expected_speaker)
    # The speaker block computed from capture k is played while capture k + 2 is taken.
    played = np.concatenate((np.zeros(2 * BLOCK, np.int16), expected_speaker[:-2 * BLOCK]))
    ear_model = fixed_reference(fb_plan.fixed, played).astype(np.int32)
    expected_d = np.clip(ear.astype(np.int32) - ear_model, -32768, 32767).astype(np.int16)
    np.testing.assert_array_equal(np.concatenate(d_hat), expected_d)


def test_speaker_dc_headroom_of_the_disturbance_estimate(runtime):
    """The FB model's DC gain (738) leaves FB_DC_HEADROOM_LSB (44 LSB) of speaker DC before the
    internal model saturates; beyond it the runtime counts the saturated samples."""
    lib, ffi = runtime
    headroom = lib.test_headroom()
    assert headroom == 32767 // 738
    counts = {}
    for level in (headroom // 2, headroom + 10):
        _memory, rt = _new(runtime, law=2)
        lib.test_set_dc(level)
        for k in range(1500):  # 48000 samples: four time constants of the slowest FB pole
            lib.anc_dma_block_done(rt, k % 2)
            lib.anc_service(rt)
        counts[level] = lib.test_saturations(rt)
    assert counts[headroom // 2] == 0 and counts[headroom + 10] > 1000
