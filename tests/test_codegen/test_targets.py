"""Every registered target (codegen.targets) through the whole pipeline, and the registry's contract.

One generic test per property, run on every target and variant, so a target added to
the registry is tested the day it is added.
"""

import numpy as np
import pytest
from conftest_codegen import appendix_a_model, model_sweeps

from codegen.build import host_filter
from codegen.context import build_context
from codegen.errors import CodegenError, VerificationError
from codegen.plan import plan_firmware
from codegen.render import render_files, template_folder
from codegen.targets import TARGETS, VARIANTS, get_target
from codegen.verify import snr_db, verify_host

CASES = [(target, key) for target in TARGETS for key in TARGETS[target].variants]


def _plan(target, variant):
    return plan_firmware(appendix_a_model("ff"), target=target, variant=variant, min_snr=0.0)


@pytest.mark.parametrize("target", list(TARGETS))
def test_templates_exist_and_variants_have_distinct_kinds(target):
    spec = get_target(target)
    for template in spec.templates:
        assert template_folder().joinpath(template).is_file()
    assert set(spec.variants) <= set(VARIANTS)
    assert len({v.kind for v in spec.variants.values()}) == len(spec.variants)
    assert spec.selected("both") == list(spec.variants.values())


@pytest.mark.parametrize("target, key", CASES)
def test_variant_plans_renders_and_verifies_alone(target, key):
    """Each variant alone: its design fills its plan field, the C renders, the host run equals its reference."""
    plan = _plan(target, key)
    variant = get_target(target).variants[key]
    assert list(plan.predictions) == [key]
    assert plan.design(key) is getattr(plan, variant.plan_field)
    context = build_context(name="ff", provenance=plan.provenance, fs=plan.realisation.fs, cascade=plan.cascade,
                            variants=tuple(plan.predictions), fixed=plan.fixed, floating=plan.floating,
                            cmsis=plan.cmsis, target=target)
    files = render_files(context, target)
    assert set(files) == {"ff_filter.h", "ff_filter.c"}
    assert f"ff_{variant.kind}_process" in files["ff_filter.h"]
    try:
        host = host_filter(plan.spec.host, "ff", files, plan.designs)
    except VerificationError as exc:  # a library target whose host twin is not installed
        pytest.skip(str(exc))
    sweep = model_sweeps(appendix_a_model("ff"), seconds=0.1)[0]
    figures = verify_host(plan, host, [sweep])["sweeps"][0][key]
    # A sweep peaking at half scale: 6 dB below the prediction's full-scale sine, 15 dB allowed beyond.
    assert figures["snr_vs_float64_db"] > plan.predictions[key].snr_db - 21
    assert ("max_lsb_difference" in figures) == variant.exact


@pytest.mark.parametrize("target, key", CASES)
def test_reference_follows_the_model(target, key):
    """The variant's Python reference against the float64 model on a sweep: the prediction's ballpark."""
    plan = _plan(target, key)
    variant = plan.spec.variants[key]
    from codegen.reference import float64_reference

    u = model_sweeps(appendix_a_model("ff"), seconds=0.1, peak=0.5)[1]
    x = variant.to_input(u)
    out = variant.to_float(variant.reference(plan.design(key), x))
    exact = float64_reference(plan.realisation, np.asarray(variant.to_float(x), float))
    # A half-scale sweep is 6 dB below the full-scale sine of the prediction; allow 15 dB more.
    assert snr_db(exact, out) > plan.predictions[key].snr_db - 21


@pytest.mark.parametrize("target", list(TARGETS))
def test_manifest_formats_name_the_design(target):
    plan = _plan(target, "both")
    formats = plan.spec.formats(plan)
    assert formats
    assert all(isinstance(entry, dict) and entry for entry in formats.values())


def test_unknown_target_names_the_choices():
    with pytest.raises(CodegenError, match=r"--target must be one of generic, cmsis; found 'dsp'"):
        get_target("dsp")
    with pytest.raises(CodegenError, match=r"--variant must be one of float, q15, both; found 'q31'"):
        get_target("generic").selected("q31")
