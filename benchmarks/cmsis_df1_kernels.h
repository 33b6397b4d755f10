/* Comparison kernels of the Cortex-M4 benchmark: CMSIS-DSP's documented DF1 Q31 algorithms (see the .c). */
#ifndef CMSIS_DF1_KERNELS_H
#define CMSIS_DF1_KERNELS_H
#include <stdint.h>

typedef struct {
    uint32_t stages;
    int32_t *state;        /* 4 per stage: x[n-1], x[n-2], y[n-1], y[n-2] */
    const int32_t *coeffs; /* 5 per stage: b0, b1, b2, a1, a2 (Q31, times 2^-post_shift) */
    uint32_t post_shift;
} df1_q31_state;

typedef struct {
    uint32_t stages;
    int64_t *state; /* 4 per stage: x[n-1], x[n-2] (Q31 in 64 bits), y[n-1], y[n-2] (Q63) */
    const int32_t *coeffs;
    uint32_t post_shift;
} df1_32x64_q31_state;

void df1_q31_plain(const df1_q31_state *s, const int32_t *src, int32_t *dst, uint32_t n);
void df1_q31_unrolled(const df1_q31_state *s, const int32_t *src, int32_t *dst, uint32_t n);
void df1_32x64_q31(const df1_32x64_q31_state *s, const int32_t *src, int32_t *dst, uint32_t n);
#endif
