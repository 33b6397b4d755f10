"""The kinds of generated code and what each needs, in one place.

A :class:`Target` is what ``--target`` names: the templates it renders, the scaling
it must use, the template fields it adds, how its C is run on the host for
verification and what its manifest says about its number formats. Its
:class:`Variant` objects are what ``--variant`` picks inside it ('q15', 'float'):
each knows how to design its coefficients from the scaled cascade, how to predict
its output noise, its Python reference (bit-exact for the integer variants), how its
samples are converted, how closely the C must match the reference, and which
functions of the generated C carry its cost per section (for the emulated
Cortex-M4 count of :mod:`codegen.qemu_cost`).

Adding a kind of generated code means adding one Target (or Variant) here; the
plan, context, rendering, verification and manifest code only ask the registry
(:func:`get_target`). This module describes; the steps of firmware generation
(plan -> context -> render -> build -> verify -> manifest) use the descriptions,
and it imports none of them: the design modules, the Python references and
:mod:`codegen.c_syntax` only. How a target's code is run on the host is named
here (``Target.host``) and done by :mod:`codegen.build`.

The controller filters (:mod:`codegen.controller`) are the generic target's
variants under fixed names; filters that need templates or numbers of their own
become a Target whose ``variants`` reuse ``FIXED_Q15`` and ``FLOAT32`` (or new
Variants) with its own ``templates``, ``context`` and ``formats``. Registered:

``generic``  plain C99: Q15 direct-form-I sections with error feedback
             (:mod:`codegen.fixedpoint`) and float32 sections written around z = 1
             (:mod:`codegen.float32`); templates ``filter.h.j2``/``filter.c.j2``.
``cmsis``    coefficient tables and calls of CMSIS-DSP's biquad kernels
             (:mod:`codegen.cmsis`): the cheapest of its Q15/Q31/32x64 DF1 kernels
             that meets ``--min-snr``, and its float32 DF2T kernel.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from . import noise
from .c_syntax import float_literal
from .cmsis import KERNEL_FUNCTIONS, KERNELS, cmsis_q15_reference, design_cmsis, df2t_f32_reference
from .errors import CodegenError, PrecisionError
from .fixedpoint import design_fixed
from .float32 import design_float32
from .realise import Realisation
from .reference import fixed_reference, float32_reference, from_q15, to_q15
from .sections import Cascade

__all__ = ["TARGETS", "VARIANTS", "Designed", "DesignInputs", "Target", "Variant", "get_target", "refusal_reason"]

# What --variant accepts: one variant, or both of a target's.
VARIANTS = ("float", "q15", "both")
# Tolerance between float C code and its float32 reference, relative to max(1, peak output).
FLOAT_TOLERANCE = 1e-6
# The cmsisdsp package's DF2T kernel orders its float operations differently (and may fuse them).
CMSIS_FLOAT_TOLERANCE = 1e-4


@dataclass(frozen=True)
class DesignInputs:
    """Everything a variant's design needs: the scaled cascade of the realised model and the request."""

    cascade: Cascade
    realisation: Realisation
    polynomial: tuple | None
    quantiser: str
    min_snr: float


@dataclass(frozen=True)
class Designed:
    """A variant's design, its predicted output noise and, for a kernel choice, every candidate's."""

    design: object
    prediction: noise.Prediction
    kernel_predictions: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Variant:
    """One kind of generated code inside a target: a number format and its algorithm.

    ``key``         'q15' or 'float': the --variant name and the key of its predictions,
                    manifest entries and verification figures;
    ``kind``        the generated C's function infix (``NAME_<kind>_process``);
    ``plan_field``  the :class:`codegen.plan.Plan` attribute that holds its design;
    ``design``      DesignInputs -> Designed (raises PrecisionError when it cannot be built);
    ``reference``   (design, input samples) -> output samples of its Python twin;
    ``to_input``    full-scale float64 -> the samples the C takes; ``to_float`` back;
    ``tolerance``   None: the C must equal the reference sample for sample (integers);
                    else the largest difference relative to max(1, peak output);
    ``cost_functions`` (name, design) -> per-section functions of the generated C whose
                    executed instructions are its per-section cost (empty: the process
                    function as a whole).
    """

    key: str
    kind: str
    plan_field: str
    design: Callable[[DesignInputs], Designed]
    reference: Callable[[object, np.ndarray], np.ndarray]
    to_input: Callable[[np.ndarray], np.ndarray]
    to_float: Callable[[np.ndarray], np.ndarray]
    tolerance: float | None
    cost_functions: Callable[[str, object], tuple[str, ...]] = lambda name, design: ()

    @property
    def exact(self) -> bool:
        return self.tolerance is None


@dataclass(frozen=True)
class Target:
    """What ``--target NAME`` generates (see the module docstring).

    ``templates``   (header, source) template names rendered to NAME_filter.h/.c;
    ``variants``    its variants by key, in the order they are designed and reported;
    ``scaling``     the section scaling norm it requires (None: the user's choice);
    ``context``     designs by plan field -> the template fields only this target uses;
    ``formats``     plan -> the manifest's "formats" entries of this target;
    ``host``        how the generated code is run on the host for verification, a runner of
                    :func:`codegen.build.host_filter`: 'cffi' (the C compiled for the host) or
                    'cmsisdsp' (the ``cmsisdsp`` package's kernels on the target's tables).
    """

    name: str
    description: str
    templates: tuple[str, str]
    variants: dict[str, Variant]
    scaling: str | None
    context: Callable[[dict], dict]
    formats: Callable[[object], dict]
    host: str

    def selected(self, variant: str) -> list[Variant]:
        """The variants --variant asks for ('both': all of this target's)."""
        if variant not in VARIANTS:
            raise CodegenError(f"--variant must be one of {', '.join(VARIANTS)}; found {variant!r}")
        return [v for key, v in self.variants.items() if variant in (key, "both")]


def refusal_reason(what: str, prediction: noise.Prediction, min_snr: float) -> str:
    """The one-line reason a design is refused for missing --min-snr, naming what limits it."""
    cause = ("coefficient quantisation" if prediction.coefficient_snr_db < prediction.roundoff_snr_db
             else "round-off noise (output quantiser and section round-off)")
    return (f"{what} refused: predicted SNR {prediction.snr_db:.1f} dB is below --min-snr {min_snr:g} dB; "
            f"limited by {cause} (coefficients {prediction.coefficient_snr_db:.1f} dB, "
            f"round-off {prediction.roundoff_snr_db:.1f} dB)")


# --- generic: the generator's own C ------------------------------------------------------------

def _design_fixed(inputs: DesignInputs) -> Designed:
    if inputs.quantiser == "round" and any(s.poles for s in inputs.cascade.sections):
        # Rounding to nearest inside a recursive section is a nonlinearity that can sustain a zero-input
        # limit cycle (Oppenheim & Schafer, Discrete-Time Signal Processing, zero-input limit cycles). Floor
        # with first-order error feedback leaves none in the appendix-A models' filters (the residue fed back
        # makes their state decay to 0: ``test_error_feedback_decays_to_exact_zero``), but a long cascade can keep
        # a wave of the size of its predicted round-off (random helmet 2/1002's W, 44 sections: -36 dBFS rms at
        # zero input).
        raise PrecisionError("--quantiser round refused: rounding in a recursive section leaves a zero-input limit "
                             "cycle (a constant hum of a few LSB); use --quantiser efb (the default)")
    design = design_fixed(inputs.cascade, inputs.realisation.delay, inputs.polynomial, inputs.quantiser)
    return Designed(design, noise.predict_fixed(inputs.cascade, design, inputs.realisation.fs))


def _design_float32(inputs: DesignInputs) -> Designed:
    design = design_float32(inputs.cascade, inputs.realisation.delay, inputs.polynomial)
    return Designed(design, noise.predict_float32(inputs.cascade, design, inputs.realisation.fs))


def _float32(x: np.ndarray) -> np.ndarray:
    return np.asarray(x, np.float32)


def _as_float(x: np.ndarray) -> np.ndarray:
    return np.asarray(x, float)


FIXED_Q15 = Variant(key="q15", kind="q15", plan_field="fixed", design=_design_fixed, reference=fixed_reference,
                    to_input=to_q15, to_float=from_q15, tolerance=None,
                    cost_functions=lambda name, design: tuple(f"{name}_q15_section{k}"
                                                              for k in range(len(design.sections))))
FLOAT32 = Variant(key="float", kind="f32", plan_field="floating", design=_design_float32, reference=float32_reference,
                  to_input=_float32, to_float=_as_float, tolerance=FLOAT_TOLERANCE)


def _generic_formats(plan) -> dict:
    formats = {}
    if plan.fixed is not None:
        fixed = plan.fixed
        formats["q15"] = {
            "input": "Q15 (int16)", "output": "Q15 (int16), rounded, saturated", "states": "Q31 (int32)",
            "accumulator": "int64, output in its high word", "form": "direct form I",
            "coefficients": "int32: B = b 2^b_exponent, A = -a 2^a_exponent",
            "quantiser": fixed.quantiser, "polynomial": fixed.polynomial,
            "polynomial_exponent": fixed.polynomial_exponent,
            "sections": [{"order": s.order, "b": list(s.b), "a": list(s.a), "guard": s.guard,
                          "feedback_shift": s.feedback_shift, "b_exponent": s.b_exponent, "a_exponent": s.a_exponent}
                         for s in fixed.sections]}
    if plan.floating is not None:
        formats["float"] = {
            "input": "float32 full scale", "output": "float32 full scale", "polynomial": plan.floating.polynomial,
            "form": ("two poles: balanced state space, N = A - I, g = B, c = C, b[0] = D; otherwise the numerator "
                     "around z = 1 (b0, b(1), b0 - b2) and one pole as k1 = -(1 + a1) (codegen.float32)"),
            "sections": [{"order": s.order, "taps": s.taps, "b": list(s.b), "c": list(s.c), "n": list(s.n),
                          "g": list(s.g)} for s in plan.floating.sections]}
    return formats


GENERIC = Target(name="generic", description="generic C99 (Q15 and float32)", templates=("filter.h.j2", "filter.c.j2"),
                 variants={"q15": FIXED_Q15, "float": FLOAT32}, scaling=None, context=lambda designs: {},
                 formats=_generic_formats, host="cffi")


# --- cmsis: tables for CMSIS-DSP's kernels ------------------------------------------------------

def _design_cmsis_q15(inputs: DesignInputs) -> Designed:
    """The cheapest CMSIS kernel whose predicted SNR meets the request."""
    tables = design_cmsis(inputs.cascade, inputs.realisation.delay, inputs.polynomial)
    fs = inputs.realisation.fs
    kernel_predictions = {k: noise.predict_cmsis(inputs.cascade, replace(tables, kernel=k), fs) for k in KERNELS}
    good = [k for k in KERNELS if kernel_predictions[k].snr_db >= inputs.min_snr]
    if not good:
        best = max(KERNELS, key=lambda k: kernel_predictions[k].snr_db)
        raise PrecisionError(refusal_reason(f"q15 variant (best CMSIS kernel {KERNEL_FUNCTIONS[best]})",
                                            kernel_predictions[best], inputs.min_snr))
    return Designed(replace(tables, kernel=good[0]), kernel_predictions[good[0]], kernel_predictions)


def _design_cmsis_f32(inputs: DesignInputs) -> Designed:
    tables = design_cmsis(inputs.cascade, inputs.realisation.delay, inputs.polynomial)
    return Designed(tables, noise.predict_cmsis_f32(inputs.cascade, tables, inputs.realisation.fs))


CMSIS_Q15 = Variant(key="q15", kind="q15", plan_field="cmsis", design=_design_cmsis_q15,
                    reference=cmsis_q15_reference, to_input=to_q15, to_float=from_q15, tolerance=None)
CMSIS_F32 = Variant(key="float", kind="f32", plan_field="cmsis", design=_design_cmsis_f32,
                    reference=df2t_f32_reference, to_input=_float32, to_float=_as_float,
                    tolerance=CMSIS_FLOAT_TOLERANCE)


def _cmsis_context(designs: dict) -> dict:
    cmsis = designs["cmsis"]
    return {
        "kernel": cmsis.kernel,
        "kernel_is_q15": cmsis.kernel == "q15",
        "kernel_is_q31": cmsis.kernel == "q31",
        "kernel_function": KERNEL_FUNCTIONS[cmsis.kernel],
        "q15_post_shift": cmsis.q15_post_shift,
        # The Q15 kernel's rows carry a zero after b0 (CMSIS-DSP's layout for its dual 16-bit MACs).
        "cmsis_q15": [[f"(q15_t){v}" for v in (row[0], 0, *row[1:])] for row in cmsis.q15_coefficients],
        "post_shift": cmsis.post_shift,
        "output_shift": cmsis.output_shift,
        "output_scale": str(2**cmsis.output_shift),
        "cmsis_q31": [[f"(q31_t){v}" if v != -(2**31) else "(q31_t)(-2147483647 - 1)" for v in row]
                      for row in cmsis.q31_coefficients],
        "cmsis_f32": [[float_literal(v) for v in row] for row in cmsis.f32_coefficients],
    }


def _cmsis_formats(plan) -> dict:
    cmsis = plan.cmsis
    return {"cmsis": {
        "kernels": {"q15": KERNEL_FUNCTIONS[cmsis.kernel], "float": "arm_biquad_cascade_df2T_f32"},
        "kernel": cmsis.kernel,
        "kernel_predictions": {KERNEL_FUNCTIONS[k]: v.as_dict() for k, v in plan.kernel_predictions.items()},
        "post_shift": cmsis.post_shift,
        "output_shift": cmsis.output_shift,
        "q31_coefficients": [list(r) for r in cmsis.q31_coefficients],
        "q15_post_shift": cmsis.q15_post_shift,
        "q15_coefficients": [list(r) for r in cmsis.q15_coefficients],
        "f32_coefficients": [list(r) for r in cmsis.f32_coefficients]}}


CMSIS = Target(name="cmsis", description="coefficient tables for CMSIS-DSP's biquad functions",
               templates=("cmsis_filter.h.j2", "cmsis_filter.c.j2"), variants={"q15": CMSIS_Q15, "float": CMSIS_F32},
               # CMSIS-DSP's Q31 kernels wrap on overflow: only worst-case (l1) scaling makes that impossible.
               # Its C needs CMSIS-DSP's headers and library, which the host build does not have: the
               # cmsisdsp package runs the same kernels on the same tables.
               scaling="l1", context=_cmsis_context, formats=_cmsis_formats, host="cmsisdsp")


TARGETS = {target.name: target for target in (GENERIC, CMSIS)}


def get_target(name: str) -> Target:
    """The registered target called ``name``, or a CodegenError naming the choices."""
    if name not in TARGETS:
        raise CodegenError(f"--target must be one of {', '.join(TARGETS)}; found {name!r}")
    return TARGETS[name]
