"""Shared helpers of the codegen and firmware tests: plants, sweeps, tool checks.

Imported explicitly by the test modules (``from conftest_codegen import ...``);
sweeps are synthesised here so the tests need no recordings.
"""

from __future__ import annotations

import shutil

import numpy as np
import scipy.signal

from sysid.core.model import Model
from sysid.core.plants import appendix_a_model

__all__ = ["CMSIS_DECLARATIONS", "FS", "appendix_a_model", "have", "log_sweep", "model_sweeps", "random_stable_model"]

FS = 44100.0


def log_sweep(seconds: float = 0.25, fs: float = FS, f0: float = 20.0, f1: float = 4000.0) -> np.ndarray:
    """Unit-amplitude exponential sweep f0 -> f1 Hz."""
    t = np.arange(int(seconds * fs)) / fs
    return scipy.signal.chirp(t, f0, t[-1], f1, method="logarithmic")


def model_sweeps(model: Model, seconds: float = 0.25, peak: float = 0.5) -> list[np.ndarray]:
    """Two validation-like sweeps (exponential, then linear) scaled so the model output peaks at ``peak``."""
    sweeps = []
    for method in ("logarithmic", "linear"):
        t = np.arange(int(seconds * model.fs)) / model.fs
        s = scipy.signal.chirp(t, 20.0, t[-1], 4000.0, method=method)
        s *= min(1.0, peak / np.max(np.abs(model.simulate(s))))
        sweeps.append(s)
    return sweeps


def random_stable_model(seed: int, order: int, path: str = "fb", delay: int = 0, radius_max: float = 0.999,
                        strictly_proper: bool = True) -> Model:
    """Random real model with poles in a ring close to the unit circle (seeded)."""
    rng = np.random.default_rng(seed)
    poles = []
    while len(poles) < order:
        r = rng.uniform(0.9, radius_max)
        if order - len(poles) >= 2 and rng.random() < 0.7:
            theta = rng.uniform(0.005, 0.6)
            poles += [r * np.exp(1j * theta), r * np.exp(-1j * theta)]
        else:
            poles.append(r)
    from sysid.core.lti import real_block_diagonal

    A = real_block_diagonal(np.array(poles))
    B = rng.standard_normal((order, 1))
    C = rng.standard_normal((1, order))
    D = np.zeros((1, 1)) if strictly_proper else rng.standard_normal((1, 1))
    return Model(path=path, fs=FS, A=A, B=B, C=C, D=D, delay=delay)


def have(tool: str) -> bool:
    return shutil.which(tool) is not None


# Declarations of the CMSIS-DSP API the cmsis target calls (names, types and
# signatures as documented for CMSIS-DSP 1.x), enough to compile the target's C.
CMSIS_DECLARATIONS = """
#ifndef ARM_MATH_H
#define ARM_MATH_H
#include <stdint.h>
typedef int16_t q15_t;
typedef int32_t q31_t;
typedef int64_t q63_t;
typedef float float32_t;
typedef struct { int8_t numStages; q15_t *pState; const q15_t *pCoeffs; int8_t postShift; } arm_biquad_casd_df1_inst_q15;
typedef struct { uint8_t numStages; q63_t *pState; const q31_t *pCoeffs; uint8_t postShift; } arm_biquad_cas_df1_32x64_ins_q31;
void arm_biquad_cascade_df1_init_q15(arm_biquad_casd_df1_inst_q15 *S, uint8_t numStages, const q15_t *pCoeffs,
                                     q15_t *pState, int8_t postShift);
void arm_biquad_cascade_df1_q15(const arm_biquad_casd_df1_inst_q15 *S, const q15_t *pSrc, q15_t *pDst, uint32_t blockSize);
void arm_biquad_cas_df1_32x64_init_q31(arm_biquad_cas_df1_32x64_ins_q31 *S, uint8_t numStages, const q31_t *pCoeffs,
                                       q63_t *pState, uint8_t postShift);
void arm_biquad_cas_df1_32x64_q31(const arm_biquad_cas_df1_32x64_ins_q31 *S, const q31_t *pSrc, q31_t *pDst,
                                  uint32_t blockSize);
typedef struct { uint32_t numStages; q31_t *pState; const q31_t *pCoeffs; uint8_t postShift; } arm_biquad_casd_df1_inst_q31;
typedef struct { uint8_t numStages; float32_t *pState; const float32_t *pCoeffs; } arm_biquad_cascade_df2T_instance_f32;
void arm_biquad_cascade_df1_init_q31(arm_biquad_casd_df1_inst_q31 *S, uint8_t numStages, const q31_t *pCoeffs,
                                     q31_t *pState, int8_t postShift);
void arm_biquad_cascade_df1_q31(const arm_biquad_casd_df1_inst_q31 *S, const q31_t *pSrc, q31_t *pDst, uint32_t blockSize);
void arm_biquad_cascade_df2T_init_f32(arm_biquad_cascade_df2T_instance_f32 *S, uint8_t numStages,
                                      const float32_t *pCoeffs, float32_t *pState);
void arm_biquad_cascade_df2T_f32(const arm_biquad_cascade_df2T_instance_f32 *S, const float32_t *pSrc,
                                 float32_t *pDst, uint32_t blockSize);
#endif
"""
