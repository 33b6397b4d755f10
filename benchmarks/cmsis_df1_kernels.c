/*
 * Comparison kernels for the emulated Cortex-M4 benchmark (bench_codegen.py): the
 * algorithms of CMSIS-DSP's arm_biquad_cascade_df1_q31 (4x unrolled and plain
 * loop) and arm_biquad_cas_df1_32x64_q31, written here from ARM's published
 * documentation of those functions (CMSIS-DSP reference, "Biquad Cascade IIR
 * Filters Using Direct Form I Structure" and "High Precision Q31 Biquad Cascade
 * Filter"), not from ARM's sources; CMSIS-DSP is not installed here.
 *
 * Documented algorithm, per stage, with coefficients {b0, b1, b2, a1, a2} in Q31
 * scaled by 2^-postShift (a1, a2 are CMSIS's negated feedback coefficients) and
 * states {x[n-1], x[n-2], y[n-1], y[n-2]}:
 *   acc (64-bit) = b0 x[n] + b1 x[n-1] + b2 x[n-2] + a1 y[n-1] + a2 y[n-2]
 *   y[n] = (q31)(acc >> (31 - postShift))          (no saturation: it wraps)
 * Stages run one after the other over the whole block, in place in pDst. The
 * unrolled loop takes 4 samples per pass and rotates the roles of the state
 * variables instead of moving them. The 32x64 variant keeps y[n-1], y[n-2] as
 * 64-bit values (acc << (postShift + 1)) multiplied by a1, a2 in 32x64 bits
 * (unsigned low word times a, shifted down 32, plus signed high word times a),
 * and outputs the high word.
 *
 * Bit-exact against codegen.cmsis.q31_kernel / q31x64_kernel (the benchmark checks).
 */
#include <stddef.h>
#include <stdint.h>
#include "arm_math.h"
#include "cmsis_df1_kernels.h"

void df1_q31_plain(const df1_q31_state *s, const int32_t *src, int32_t *dst, uint32_t n)
{
    const int32_t *coeffs = s->coeffs;
    int32_t *state = s->state;
#ifdef DF1_CONSTANT_POST_SHIFT
    /* The best case for the comparison: postShift known to the compiler (the library reads it at run time). */
    const uint32_t shift = 31u - DF1_CONSTANT_POST_SHIFT;
    (void)s->post_shift;
#else
    uint32_t shift = 31u - s->post_shift;
#endif
    uint32_t stage;
    for (stage = 0; stage < s->stages; ++stage) {
        int32_t b0 = coeffs[0], b1 = coeffs[1], b2 = coeffs[2], a1 = coeffs[3], a2 = coeffs[4];
        int32_t x1 = state[0], x2 = state[1], y1 = state[2], y2 = state[3];
        const int32_t *in = src;
        int32_t *out = dst;
        uint32_t i;
        for (i = 0; i < n; ++i) {
            int32_t x0 = *in++;
            int64_t acc = (int64_t)b0 * x0 + (int64_t)b1 * x1 + (int64_t)b2 * x2 + (int64_t)a1 * y1
                          + (int64_t)a2 * y2;
            int32_t y0 = (int32_t)(acc >> shift);
            x2 = x1;
            x1 = x0;
            y2 = y1;
            y1 = y0;
            *out++ = y0;
        }
        state[0] = x1;
        state[1] = x2;
        state[2] = y1;
        state[3] = y2;
        state += 4;
        coeffs += 5;
        src = dst;
    }
}

/* One output of the unrolled loop; the callers pass the state variables in their current roles. */
#define DF1_STEP(x0, x1, x2, y1, y2, y0)                                                          \
    do {                                                                                          \
        int64_t acc_ = (int64_t)b0 * (x0) + (int64_t)b1 * (x1) + (int64_t)b2 * (x2)               \
                       + (int64_t)a1 * (y1) + (int64_t)a2 * (y2);                                 \
        (y0) = (int32_t)(acc_ >> shift);                                                          \
    } while (0)

void df1_q31_unrolled(const df1_q31_state *s, const int32_t *src, int32_t *dst, uint32_t n)
{
    const int32_t *coeffs = s->coeffs;
    int32_t *state = s->state;
#ifdef DF1_CONSTANT_POST_SHIFT
    /* The best case for the comparison: postShift known to the compiler (the library reads it at run time). */
    const uint32_t shift = 31u - DF1_CONSTANT_POST_SHIFT;
    (void)s->post_shift;
#else
    uint32_t shift = 31u - s->post_shift;
#endif
    uint32_t stage;
    for (stage = 0; stage < s->stages; ++stage) {
        int32_t b0 = coeffs[0], b1 = coeffs[1], b2 = coeffs[2], a1 = coeffs[3], a2 = coeffs[4];
        int32_t x0, x1 = state[0], x2 = state[1], y1 = state[2], y2 = state[3];
        const int32_t *in = src;
        int32_t *out = dst;
        uint32_t blocks = n >> 2, rest = n & 3u;
        while (blocks-- > 0u) {
            /* Each new input goes to the variable of the oldest x, each output to that of the oldest y. */
            x0 = *in++;
            DF1_STEP(x0, x1, x2, y1, y2, y2);
            *out++ = y2;
            x2 = *in++;
            DF1_STEP(x2, x0, x1, y2, y1, y1);
            *out++ = y1;
            x1 = *in++;
            DF1_STEP(x1, x2, x0, y1, y2, y2);
            *out++ = y2;
            x0 = *in++;
            DF1_STEP(x0, x1, x2, y2, y1, y1);
            *out++ = y1;
            /* Newest input in x0, the one before in x1: back to the roles at the top of the loop. */
            x2 = x1;
            x1 = x0;
        }
        while (rest-- > 0u) {
            x0 = *in++;
            DF1_STEP(x0, x1, x2, y1, y2, y2);
            *out++ = y2;
            x2 = x1;
            x1 = x0;
            /* Newest output in y2: swap the roles back. */
            y2 = y1 ^ y2;
            y1 = y1 ^ y2;
            y2 = y1 ^ y2;
        }
        state[0] = x1;
        state[1] = x2;
        state[2] = y1;
        state[3] = y2;
        state += 4;
        coeffs += 5;
        src = dst;
    }
}

/* (x * a) for a 64-bit x and a Q31 a, shifted down 32 bits: unsigned low word and signed high word apart. */
static inline int64_t mult_32x64(int64_t x, int32_t a)
{
    return (int64_t)(((int64_t)(uint32_t)(x & 0xFFFFFFFF) * a) >> 32) + (x >> 32) * a;
}

void df1_32x64_q31(const df1_32x64_q31_state *s, const int32_t *src, int32_t *dst, uint32_t n)
{
    const int32_t *coeffs = s->coeffs;
    int64_t *state = s->state;
    uint32_t up = s->post_shift + 1u;
    uint32_t stage;
    for (stage = 0; stage < s->stages; ++stage) {
        int32_t b0 = coeffs[0], b1 = coeffs[1], b2 = coeffs[2], a1 = coeffs[3], a2 = coeffs[4];
        int32_t x1 = (int32_t)state[0], x2 = (int32_t)state[1];
        int64_t y1 = state[2], y2 = state[3];
        const int32_t *in = src;
        int32_t *out = dst;
        uint32_t i;
        for (i = 0; i < n; ++i) {
            int32_t x0 = *in++;
            int64_t acc = (int64_t)b0 * x0 + (int64_t)b1 * x1 + (int64_t)b2 * x2;
            acc += mult_32x64(y1, a1) + mult_32x64(y2, a2);
            /* The 64-bit state is the accumulator scaled back to Q63; its high word is the Q31 output. */
            acc = (int64_t)((uint64_t)acc << up);
            x2 = x1;
            x1 = x0;
            y2 = y1;
            y1 = acc;
            *out++ = (int32_t)(acc >> 32);
        }
        state[0] = x1;
        state[1] = x2;
        state[2] = y1;
        state[3] = y2;
        state += 4;
        coeffs += 5;
        src = dst;
    }
}

/* The CMSIS-DSP API of the two Q31 kernels (arm_math.h here), so that the cmsis target's generated
 * C runs on the emulator: the documented init (states zeroed) and process calls, the process call
 * running the 4x unrolled algorithm as the library does on Cortex-M4. */
void arm_biquad_cascade_df1_init_q31(arm_biquad_casd_df1_inst_q31 *S, uint8_t numStages, const q31_t *pCoeffs,
                                     q31_t *pState, int8_t postShift)
{
    uint32_t k;
    S->numStages = numStages;
    S->pCoeffs = pCoeffs;
    S->pState = pState;
    S->postShift = (uint8_t)postShift;
    for (k = 0; k < 4u * numStages; ++k) {
        pState[k] = 0;
    }
}

void arm_biquad_cascade_df1_q31(const arm_biquad_casd_df1_inst_q31 *S, const q31_t *pSrc, q31_t *pDst,
                                uint32_t blockSize)
{
    const df1_q31_state s = {S->numStages, S->pState, S->pCoeffs, S->postShift};
    df1_q31_unrolled(&s, pSrc, pDst, blockSize);
}

void arm_biquad_cas_df1_32x64_init_q31(arm_biquad_cas_df1_32x64_ins_q31 *S, uint8_t numStages, const q31_t *pCoeffs,
                                       q63_t *pState, uint8_t postShift)
{
    uint32_t k;
    S->numStages = numStages;
    S->pCoeffs = pCoeffs;
    S->pState = pState;
    S->postShift = postShift;
    for (k = 0; k < 4u * numStages; ++k) {
        pState[k] = 0;
    }
}

void arm_biquad_cas_df1_32x64_q31(const arm_biquad_cas_df1_32x64_ins_q31 *S, const q31_t *pSrc, q31_t *pDst,
                                  uint32_t blockSize)
{
    const df1_32x64_q31_state s = {S->numStages, S->pState, S->pCoeffs, S->postShift};
    df1_32x64_q31(&s, pSrc, pDst, blockSize);
}
