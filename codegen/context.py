"""The plain data the templates render: names, literals, sizes and flags of one filter.

Second step of firmware generation (plan -> context -> render -> build -> verify ->
manifest): :func:`build_context` turns a plan's designs into a dictionary of strings,
numbers and lists (every C expression fragment prepared here, through
:mod:`codegen.c_syntax`), and :func:`controller_config_context` does the same for a
controller's ``controller_config.h``. It imports the designs' types and the target
descriptions (:mod:`codegen.targets`, for the fields only one target's templates
use), nothing of the steps after it.
"""

from __future__ import annotations

import math

import numpy as np

from . import __version__
from .c_syntax import comment_text, float_literal, int_literal, validate_name
from .fixedpoint import FixedDesign
from .float32 import FloatDesign
from .targets import get_target

__all__ = ["build_context", "controller_config_context"]


def _product(state: str, coefficient: int, table: list | None = None) -> str:
    """A 32 x 32 -> 64-bit product the compiler maps to SMULL/SMLAL: with the coefficient as a
    literal, or, given ``table``, appended to it and read as ``c[index]``."""
    if table is None:
        return f"(int64_t){state} * {int_literal(coefficient, 'INT32_C')}"
    table.append(int(coefficient))
    return f"(int64_t){state} * c[{len(table) - 1}]"


def _fixed_step(section, quantiser: str, x: tuple[str, str, str], y: tuple[str, str], out: str,
                table: list | None = None) -> dict:
    """One sample of a section with the state variables in the given roles: x = (x[n], x[n-1],
    x[n-2]), y = (y[n-1], y[n-2]); the output goes to ``out``. With ``table`` the coefficients
    are read from the table (see :func:`_product`)."""
    # Feedback first: the table then holds the coefficients in the order of the products below.
    feedback = [_product(state, a, table) for state, a in zip(y, section.a) if a]
    forward = [_product(state, b, table) for state, b in zip(x, section.b) if b]
    if section.feedback_shift and feedback:
        # The feedback's extra d fractional bits: its product sum is shifted down on its own.
        return {"start": f"(({' + '.join(feedback)}) >> {section.feedback_shift}) + {quantiser}", "terms": forward,
                "input": x[0], "out": out}
    return {"start": quantiser, "terms": feedback + forward, "input": x[0], "out": out}


def _fixed_sections(design: FixedDesign) -> list[dict]:
    """Per section: the four unrolled steps and the single step of its sample loop, and the clamp.

    The single steps (the per-sample kernel, all sections in one function) read their
    coefficients from one table (``single.coefficients`` are each section's entries, in table
    order): loaded through one pointer they cost the same loads as literals but leave gcc the
    registers a literal pool's addressing takes (emulated Cortex-M4, seed plants' control path: 676 -> 620
    instructions per sample).

    The loop takes four samples per pass (as CMSIS-DSP's DF1 kernels do); each new input is
    read into the variable of the oldest input and each output replaces the older output, so
    the states change roles instead of being copied (after four samples the outputs are back
    in their roles and the inputs need x2 = x1, x1 = x0, fixed in the template).
    """
    rows = []
    quantiser = "(int64_t)e" if design.quantiser == "efb" else "INT64_C(2147483648)"
    roles = [(("x0", "x1", "x2"), ("y1", "y2"), "y2"), (("x2", "x0", "x1"), ("y2", "y1"), "y1"),
             (("x1", "x2", "x0"), ("y1", "y2"), "y2"), (("x0", "x1", "x2"), ("y2", "y1"), "y1")]
    table = []
    for k, section in enumerate(design.sections):
        first = len(table)
        single = _fixed_step(section, f"(int64_t)s->e[{k}]" if design.quantiser == "efb" else quantiser,
                             ("v", "x1", "x2"), ("y1", "y2"), "out", table)
        single["coefficients"] = [int_literal(c, "INT32_C") for c in table[first:]]
        rows.append({
            "index": k,
            "order": section.order,
            "guard": section.guard,
            "feedback_shift": section.feedback_shift,
            "quad": [{**_fixed_step(section, quantiser, x, y, out), "offset": offset}
                     for offset, (x, y, out) in enumerate(roles)],
            "tail": _fixed_step(section, quantiser, ("x0", "x1", "x2"), ("y1", "y2"), "y0"),
            # The short-block and per-sample path: one sample through every section; the input history x1, x2
            # is the previous section's output history (the template keeps it in registers).
            "single": single,
            "bits": 32 - section.guard,
            "unit": str(1 << section.guard),
        })
    return rows


def _sum(terms: list[str]) -> str:
    # C's + is left-associative: ((t0 + t1) + t2), the order of the Python twins.
    return " + ".join(terms) if terms else "0.0f"


def _float_sections(design: FloatDesign) -> list[dict]:
    """Per section: the C statements of :mod:`codegen.float32`'s forms, input node (v{k}, d{k}) with
    previous sample (hv{k}, hd{k}), output node (v{k+1}, d{k+1}), a two-pole section's states sa{k},
    sb{k} (its f{k+1} = D v{k}); zero coefficients left out."""
    rows = []
    for k, section in enumerate(design.sections):
        b0, m1, m2 = section.b
        taps = {3: [(b0, f"(d{k} - hd{k})"), (m1, f"hv{k}"), (m2, f"hd{k}")], 2: [(b0, f"d{k}"), (m1, f"hv{k}")],
                1: [(b0, f"v{k}")], 0: []}[section.taps]
        forward = _sum([f"{float_literal(c)} * {x}" for c, x in taps if c != 0.0])
        out, w1 = k + 1, f"hv{k + 1}"
        states = (f"sa{k}", f"sb{k}")
        if section.order == 2:
            output = [f"{float_literal(c)} * {states[i]}" for i, c in enumerate(section.c) if c != 0.0]
            lines = [f"v{out} = {_sum([f'f{out}', *output])};"]
            increments = []
            for i in range(2):
                terms = [f"{float_literal(c)} * {states[j]}" for j, c in enumerate(section.n[2 * i: 2 * i + 2]) if c != 0.0]
                if section.g[i] != 0.0:
                    terms.append(f"{float_literal(section.g[i])} * v{k}")
                if terms:
                    increments.append((i, f"i{'ab'[i]}{k}"))
                    lines.append(f"const float i{'ab'[i]}{k} = {_sum(terms)};")
            lines += [f"{states[i]} = {states[i]} + {name};" for i, name in increments]
            lines.append(f"d{out} = v{out} - {w1};")
        elif section.order == 1:
            k1 = section.c[0]
            lines = [f"d{out} = f{out} + {float_literal(k1)} * {w1};" if k1 != 0.0 else f"d{out} = f{out};",
                     f"v{out} = {w1} + d{out};"]
        else:
            lines = [f"v{out} = f{out};", f"d{out} = v{out} - {w1};"]
        rows.append({"index": k, "order": section.order, "forward": forward, "lines": lines})
    return rows


def _dc_gain(cascade) -> float:
    """Gain of the cascade at z = 1: prod_k sum(b_k) / sum(a_k) (poles at z = 1 are refused earlier)."""
    return float(np.prod([sum(s.b) / sum(s.a) for s in cascade.sections]))


def _dc_headroom_lsb(dc_gain: float) -> int:
    """Largest constant Q15 input (LSB) whose output magnitude stays at most 32767."""
    return 32767 if abs(dc_gain) <= 1.0 else int(32767 // abs(dc_gain))


def build_context(*, name: str, provenance: dict, fs: float, cascade, variants, fixed: FixedDesign | None,
                  floating: FloatDesign | None, cmsis=None, target: str = "generic") -> dict:
    """The plain dictionary the templates render: names, literals, sizes, flags.

    ``variants`` lists the variants to emit ('q15', 'float'); ``fixed``/``floating``
    carry the generic target's designs, ``cmsis`` the cmsis target's tables; the
    target (:mod:`codegen.targets`) adds the fields only its templates use.
    """
    validate_name(name)
    # Model text reaches the C only through comment_text (a whitelist).
    hash_text = comment_text(provenance.get("hash", "unknown"))
    banner = (f"Generated by helmet-anc codegen {__version__} from model {hash_text}; do not edit.")
    gamma = provenance.get("gamma")
    described = comment_text(f"path {provenance.get('path')}, file {provenance.get('file') or '(in memory)'}, "
                             f"sha256 {hash_text}, gamma {gamma if gamma is not None else 'n/a'}, "
                             f"order {provenance.get('order')}")
    poly_fixed = list(fixed.polynomial) if fixed is not None and fixed.polynomial else []
    poly_float = list(floating.polynomial) if floating is not None and floating.polynomial else []
    delay = (fixed or floating or cmsis).delay
    fixed_rows = _fixed_sections(fixed) if fixed is not None else []
    context = {
        "banner": banner,
        "provenance": described,
        "name": name,
        "NAME": name.upper(),
        "guard": f"HELMET_ANC_{name.upper()}_FILTER_H",
        "path_label": comment_text(provenance.get("path", "unknown")).upper(),
        "fs_text": format(fs, ".6g"),
        "fs_int": round(fs),
        "sections": [{"order": s.order} for s in cascade.sections],
        "nodes": list(range(len(cascade.sections) + 1)),
        "delay": delay,
        "scaling": cascade.scaling,
        "output_peak_gain": format(cascade.node_gains[-1], ".4g"),
        "dc_gain": float_literal(_dc_gain(cascade)),
        "dc_headroom_lsb": _dc_headroom_lsb(_dc_gain(cascade)),
        "output_margin_db": format(-20 * math.log10(cascade.node_gains[-1]), ".1f"),
        "headroom_db": format(cascade.headroom_db, "g"),
        "has_float": "float" in variants,
        "has_fixed": "q15" in variants,
        "efb": fixed is not None and fixed.quantiser == "efb",
        "quantiser_text": ("the previous sample's residue e = acc mod 2^32 (first-order error feedback of the "
                           "truncation residue)" if fixed is not None and fixed.quantiser == "efb"
                           else "2^31 (rounding to nearest)"),
        "polynomial": bool(poly_fixed or poly_float),
        "fixed_poly": [int_literal(p) for p in poly_fixed],
        "fixed_poly_rest": [int_literal(p) for p in poly_fixed[-2::-1]],
        "poly_exponent": fixed.polynomial_exponent if fixed is not None else 0,
        "float_poly": [float_literal(a) for a in poly_float],
        "float_poly_rest": [float_literal(a) for a in poly_float[-2::-1]],
        "fixed_sections": fixed_rows,
        # The per-sample kernel's coefficient table (none when every coefficient is zero).
        "single_coefficients": any(row["single"]["coefficients"] for row in fixed_rows),
        # One saturation function per output width the sections use (SSAT takes the width as an immediate).
        "saturations": [{"bits": bits, "top": str(2 ** (bits - 1) - 1)}
                        for bits in sorted({32 - s.guard for s in fixed.sections if s.guard})] if fixed is not None else [],
        "float_sections": _float_sections(floating) if floating is not None else [],
        # The two-pole sections' recursion states, slot by slot in the state's s[][2].
        "float_recursions": ([{"section": k, "slot": slot} for slot, k in
                              enumerate(k for k, sec in enumerate(floating.sections) if sec.order == 2)]
                             if floating is not None else []),
    }
    context.update(get_target(target).context({"fixed": fixed, "floating": floating, "cmsis": cmsis}))
    return context


def controller_config_context(plan, controller_hash: str) -> dict:
    """The plain dictionary ``controller_config.h.j2`` renders for a :class:`codegen.controller.ControllerPlan`:
    its latency, which filters exist, the board rate, the drive's worst-case margin and which variants were
    generated (a variant left out stops its build with the reason)."""
    return {
        "banner": f"Generated by helmet-anc codegen {__version__} from controller {controller_hash}; do not edit.",
        "latency": plan.latency_samples,
        "has_q": int("fb" in plan.plans),
        "has_w": int("ff" in plan.plans),
        "fs_int": round(plan.controller.fs),
        "drive_margin_db": format(plan.headroom["drive"]["margin_db"], ".1f"),
        "drive_peak": format(plan.headroom["drive"]["worst_case_peak"], ".4g"),
        "has_q15": int("q15" in plan.variants),
        "has_f32": int("float" in plan.variants),
        # A variant left out (its predicted SNR misses --min-snr in a filter): building it stops with the reason.
        "refused_q15": comment_text(plan.refused["q15"]) if "q15" in plan.refused else None,
        "refused_f32": comment_text(plan.refused["float"]) if "float" in plan.refused else None,
    }
