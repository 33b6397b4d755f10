/*
 * The part of CMSIS-DSP's API (types and biquad functions, as documented for CMSIS-DSP 1.x)
 * that the cmsis target's generated C calls, for building that C on the emulated Cortex-M4
 * in bench_codegen.py. CMSIS-DSP is not installed here: the Q31 functions are implemented in
 * cmsis_df1_kernels.c from ARM's published description of the algorithms.
 */
#ifndef ARM_MATH_H
#define ARM_MATH_H
#include <stdint.h>

typedef int16_t q15_t;
typedef int32_t q31_t;
typedef int64_t q63_t;
typedef float float32_t;

typedef struct {
    uint32_t numStages;
    q31_t *pState;
    const q31_t *pCoeffs;
    uint8_t postShift;
} arm_biquad_casd_df1_inst_q31;

typedef struct {
    uint8_t numStages;
    q63_t *pState;
    const q31_t *pCoeffs;
    uint8_t postShift;
} arm_biquad_cas_df1_32x64_ins_q31;

void arm_biquad_cascade_df1_init_q31(arm_biquad_casd_df1_inst_q31 *S, uint8_t numStages, const q31_t *pCoeffs,
                                     q31_t *pState, int8_t postShift);
void arm_biquad_cascade_df1_q31(const arm_biquad_casd_df1_inst_q31 *S, const q31_t *pSrc, q31_t *pDst,
                                uint32_t blockSize);
void arm_biquad_cas_df1_32x64_init_q31(arm_biquad_cas_df1_32x64_ins_q31 *S, uint8_t numStages, const q31_t *pCoeffs,
                                       q63_t *pState, uint8_t postShift);
void arm_biquad_cas_df1_32x64_q31(const arm_biquad_cas_df1_32x64_ins_q31 *S, const q31_t *pSrc, q31_t *pDst,
                                  uint32_t blockSize);
#endif
