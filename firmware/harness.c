/*
 * Filter harness: runs one generated filter over samples read from files and
 * writes its outputs, identically on the host and on the (emulated) board.
 *
 *   in_q15.raw   int16 little-endian input  -> out_q15.raw  (NAME_q15_process)
 *   in_f32.raw   float32 input              -> out_f32.raw  (NAME_f32_process)
 *
 * Input is fed in blocks of HARNESS_BLOCK samples, state carried over, as the
 * block callback does. Build with -DFILTER_NAME=fb -DFILTER_HEADER='"fb_filter.h"'
 * and HARNESS_Q15 and/or HARNESS_F32 (see the Makefile).
 */
#include <stddef.h>
#include <stdint.h>
#include "board_io.h"

#ifndef FILTER_NAME
#error "define FILTER_NAME (the --name of the generated filter) and FILTER_HEADER"
#endif
#define CAT2(a, b) a##_##b
#define CAT(a, b) CAT2(a, b)
#include FILTER_HEADER

#ifndef HARNESS_BLOCK
#define HARNESS_BLOCK 32u
#endif
/* Longest input the harness takes (the buffers are static: no heap on the board).
 * A longer file is refused, never truncated. */
#ifndef HARNESS_MAX_SAMPLES
#define HARNESS_MAX_SAMPLES 262144
#endif
#define HARNESS_STR2(x) #x
#define HARNESS_STR(x) HARNESS_STR2(x)

#if defined(HARNESS_Q15) || defined(HARNESS_F32)
/* Refuse input beyond HARNESS_MAX_SAMPLES (the read buffer holds one sample more to detect it). */
static int too_long(const char *file, size_t n)
{
    if (n <= HARNESS_MAX_SAMPLES) {
        return 0;
    }
    board_io_print(file);
    board_io_print(": longer than " HARNESS_STR(HARNESS_MAX_SAMPLES)
                   " samples; split it or rebuild with -DHARNESS_MAX_SAMPLES=<n>\n");
    return 1;
}
#endif

#if defined(HARNESS_Q15)
static int16_t in_q15[HARNESS_MAX_SAMPLES + 1u];
static int16_t out_q15[HARNESS_MAX_SAMPLES];

static int run_q15(void)
{
    CAT(FILTER_NAME, q15_state) state;
    size_t n, done, m;
    long bytes = board_io_read("in_q15.raw", in_q15, sizeof in_q15);
    if (bytes < 0) {
        board_io_print("cannot read in_q15.raw\n");
        return 1;
    }
    n = (size_t)bytes / sizeof in_q15[0];
    if (too_long("in_q15.raw", n)) {
        return 8;
    }
    CAT(FILTER_NAME, q15_init)(&state);
    for (done = 0; done < n; done += m) {
        m = (n - done < HARNESS_BLOCK) ? n - done : HARNESS_BLOCK;
        CAT(FILTER_NAME, q15_process)(&state, in_q15 + done, out_q15 + done, m);
    }
    return board_io_write("out_q15.raw", out_q15, n * sizeof out_q15[0]) == 0 ? 0 : 2;
}
#endif

#if defined(HARNESS_F32)
static float in_f32[HARNESS_MAX_SAMPLES + 1u];
static float out_f32[HARNESS_MAX_SAMPLES];

static int run_f32(void)
{
    CAT(FILTER_NAME, f32_state) state;
    size_t n, done, m;
    long bytes = board_io_read("in_f32.raw", in_f32, sizeof in_f32);
    if (bytes < 0) {
        board_io_print("cannot read in_f32.raw\n");
        return 1;
    }
    n = (size_t)bytes / sizeof in_f32[0];
    if (too_long("in_f32.raw", n)) {
        return 8;
    }
    CAT(FILTER_NAME, f32_init)(&state);
    for (done = 0; done < n; done += m) {
        m = (n - done < HARNESS_BLOCK) ? n - done : HARNESS_BLOCK;
        CAT(FILTER_NAME, f32_process)(&state, in_f32 + done, out_f32 + done, m);
    }
    return board_io_write("out_f32.raw", out_f32, n * sizeof out_f32[0]) == 0 ? 0 : 2;
}
#endif

int main(void)
{
    int status = 0;
    int ran = 0;
#if defined(HARNESS_Q15)
    status |= run_q15();
    ran = 1;
#endif
#if defined(HARNESS_F32)
    status |= run_f32();
    ran = 1;
#endif
    if (!ran) {
        board_io_print("harness: no variant selected (define HARNESS_Q15 and/or HARNESS_F32)\n");
        return 4;
    }
    board_io_print(status == 0 ? "harness done\n" : "harness failed\n");
    return status;
}
