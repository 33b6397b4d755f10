"""Worst-case inputs through every target's generated code: the output may saturate, never wrap.

Inputs (Q15): a full-scale step, a small DC (50 LSB) and full-scale DC, a full-scale sine at the
frequency of the model's peak gain, and full-scale uniform noise. The generic target runs its
compiled C (cffi host build); the cmsis target runs CMSIS-DSP's own kernels (``cmsisdsp``
package) on the generated tables with the generated Q31 -> Q15 conversion. Wrapping shows as
an output of the wrong sign where the ideal (float64, clipped) output is large.
"""

import numpy as np
import pytest
import scipy.signal
from conftest_codegen import appendix_a_model

from codegen.build import CmsisPackageFilter, build_host
from codegen.context import build_context
from codegen.plan import plan_firmware
from codegen.reference import delay_signal, from_q15, to_q15
from codegen.render import render_files
from sysid.core.sections import cascade_response, peak_grid

N = 24000  # longer than the FB model's slowest time constant (about 11600 samples)


def _inputs(plan):
    sections = plan.cascade.sections
    w = peak_grid([p for s in sections for p in s.poles])
    w_peak = float(w[np.argmax(np.abs(cascade_response(sections, w)))])
    n = np.arange(N)
    rng = np.random.default_rng(12)
    return {"step": np.where(n >= 100, 1.0, 0.0), "dc 50 LSB": np.full(N, 50 / 32768), "dc -full": -np.ones(N),
            "sine at peak gain": np.sin(w_peak * n), "noise": rng.uniform(-1.0, 1.0, N)}


def _ideal(plan, u_q15):
    sos = np.array([list(s.b) + list(s.a) for s in plan.cascade.sections])
    return scipy.signal.sosfilt(sos, delay_signal(from_q15(u_q15), plan.realisation.delay))


def _assert_no_wrap(y_full, ideal, label):
    """A wrap jumps the output across the range in one sample: no step of y may exceed the
    largest step of the clipped ideal output by more than a quarter of the range."""
    jump = np.max(np.abs(np.diff(y_full)))
    allowed = np.max(np.abs(np.diff(np.clip(ideal, -1.0, 1.0)))) + 0.5
    assert jump <= allowed, f"{label}: the output jumps by {jump:.3f} of full scale in one sample (wrap)"


def _generic(plan, name):
    context = build_context(name=name, provenance=plan.provenance, fs=plan.realisation.fs, cascade=plan.cascade,
                            variants=tuple(plan.predictions), fixed=plan.fixed, floating=plan.floating)
    files = render_files(context)
    return build_host(name, files[f"{name}_filter.h"], files[f"{name}_filter.c"])


@pytest.mark.parametrize("path", ["fb", "ff"])
@pytest.mark.parametrize("target, kernel", [("generic", None), ("cmsis", "q15"), ("cmsis", "q31"), ("cmsis", "q31x64")])
def test_worst_case_inputs_never_wrap(path, target, kernel):
    from dataclasses import replace

    plan = plan_firmware(appendix_a_model(path), target=target, min_snr=-1000.0)
    if target == "cmsis":
        pytest.importorskip("cmsisdsp", reason="the cmsis target is run with the cmsisdsp package's kernels")
        host = CmsisPackageFilter(replace(plan.cmsis, kernel=kernel))
    else:
        host = _generic(plan, f"wc_{path}")
    for label, x in _inputs(plan).items():
        u = to_q15(x)
        ideal = _ideal(plan, u)
        host.reset("q15")
        y = from_q15(host.process_q15(u))
        _assert_no_wrap(y, ideal, f"{target} {kernel or ''} {path} q15, {label}")
        if kernel in ("q31", "q31x64"):
            # l1-scaled, no stage can overflow: linear up to the output's saturation.
            np.testing.assert_allclose(y, np.clip(ideal, -1.0, 1.0), atol=0.02, err_msg=f"{kernel} {path} {label}")
        host.reset("f32")
        y = host.process_f32(from_q15(u).astype(np.float32)).astype(float)
        assert np.all(np.isfinite(y)), f"{target} {path} float, {label}: non-finite output"
        # float32 cannot wrap; its output follows the ideal one (not clipped) closely.
        assert np.max(np.abs(y - ideal)) < 1e-3 * max(1.0, np.max(np.abs(ideal))), f"{target} {path} float, {label}"
