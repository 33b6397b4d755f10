"""The plan's section order (codegen.plan): sections whose round-off dominates are moved to the end of the
cascade only where that at least halves the worst variant's round-off, and the moved filter is the same filter,
bit-exact in its generated C."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest_codegen import random_stable_model

from codegen import noise
from codegen.api import generate_firmware
from codegen.build import build_host
from codegen.errors import CodegenError
from codegen.plan import plan_firmware
from codegen.reference import fixed_reference, float32_reference, from_q15, to_q15
from codegen.sections import cascade_response, design_cascade
from codegen.targets import DesignInputs, get_target

HALVED_DB = 10.0 * math.log10(2.0)
# Random models (``conftest_codegen.random_stable_model``, path ff) whose round-off a few sections dominate in the
# paired order (Q15 the worse variant, then float32), and one where it is spread.
DOMINATED = [(13, 12), (41, 24), (76, 24)]
SPREAD = (1, 12)
TERMS = {"q15": noise.fixed_roundoff_terms, "float": noise.float32_roundoff_terms}


def _paired(plan) -> tuple[str, float, np.ndarray]:
    """In the paired order: the worst variant, its predicted SNR (dB) and its round-off per section."""
    cascade = design_cascade(plan.realisation, order=None)
    inputs = DesignInputs(cascade=cascade, realisation=plan.realisation, polynomial=None, quantiser="efb",
                          min_snr=-math.inf)
    designed = {v.key: v.design(inputs) for v in get_target("generic").selected("both")}
    worst = min(designed, key=lambda key: designed[key].prediction.snr_db)
    terms = np.array(TERMS[worst](cascade, designed[worst].design, plan.realisation.fs))
    return worst, designed[worst].prediction.snr_db, terms


@pytest.mark.parametrize("seed, order", DOMINATED)
def test_dominant_sections_move_last_where_that_halves_the_round_off(seed, order):
    plan = plan_firmware(random_stable_model(seed, order, path="ff"), min_snr=-math.inf)
    sections = len(plan.cascade.sections)
    assert plan.cascade.order != tuple(range(sections))
    assert sorted(plan.cascade.order) == list(range(sections))
    worst_key, paired_snr, terms = _paired(plan)
    assert min(p.snr_db for p in plan.predictions.values()) >= paired_snr + HALVED_DB
    # The moved sections are among the loudest three of the paired order's worst variant, which held more than
    # half of its round-off.
    loudest = np.argsort(terms)[::-1][:3]
    assert np.sum(terms[loudest]) > 0.5 * np.sum(terms)
    order = plan.cascade.order
    moved = {k for i, k in enumerate(order) if any(j > k for j in order[:i])}
    assert moved and moved <= set(loudest.tolist())


def test_the_worse_variant_chooses_the_sections():
    """Where float32 is the worse variant its own round-off picks the sections, and it is float32 that gains."""
    plan = plan_firmware(random_stable_model(*DOMINATED[2], path="ff"), min_snr=-math.inf)
    worst_key, paired_snr, _ = _paired(plan)
    assert worst_key == "float"
    assert plan.predictions["float"].snr_db >= paired_snr + HALVED_DB


def test_spread_round_off_keeps_the_paired_order():
    plan = plan_firmware(random_stable_model(*SPREAD, path="ff"), min_snr=-math.inf)
    assert plan.cascade.order == tuple(range(len(plan.cascade.sections)))
    paired = design_cascade(plan.realisation)
    assert plan.cascade.sections == paired.sections


@pytest.mark.parametrize("seed, order", DOMINATED)
def test_the_moved_cascade_is_the_same_filter(seed, order):
    model = random_stable_model(seed, order, path="ff")
    plan = plan_firmware(model, min_snr=-math.inf)
    w = np.linspace(1e-3, np.pi - 1e-3, 4000)
    exact = model.frequency_response(w * model.fs / (2.0 * np.pi))
    moved = cascade_response(plan.cascade.sections, w)
    assert np.max(np.abs(moved - exact)) <= 1e-9 * np.max(np.abs(exact))


def test_the_moved_cascade_runs_bit_exact_in_c(tmp_path):
    model = random_stable_model(*DOMINATED[1], path="ff")
    manifest = generate_firmware(model, tmp_path / "gen", name="moved", min_snr=0.0)
    host = build_host("moved", (tmp_path / "gen" / "moved_filter.h").read_text(),
                      (tmp_path / "gen" / "moved_filter.c").read_text())
    plan = plan_firmware(model, min_snr=0.0)
    assert plan.cascade.order != tuple(range(len(plan.cascade.sections)))
    assert manifest.name == "moved"
    # The manifest says where each section sat in the paired order.
    record = json.loads((tmp_path / "gen" / "manifest.json").read_text())["cascade"]
    assert record["paired_positions"] == list(plan.cascade.order)
    q = to_q15(np.random.default_rng(5).uniform(-0.5, 0.5, 3000))
    np.testing.assert_array_equal(host.process_q15(q), fixed_reference(plan.fixed, q))
    xf = from_q15(q).astype(np.float32)
    np.testing.assert_array_equal(host.process_f32(xf), float32_reference(plan.floating, xf))


def test_an_order_that_is_not_a_permutation_is_refused():
    plan = plan_firmware(random_stable_model(*SPREAD, path="ff"), min_snr=-math.inf)
    with pytest.raises(CodegenError, match="permutation"):
        design_cascade(plan.realisation, order=[0, 0, 1, 2, 3, 4])


@pytest.mark.parametrize("seed, order", DOMINATED)
def test_the_terms_are_the_predictions_parts(seed, order):
    """The per-section terms add up to the predicted round-off: with the output quantiser for Q15, and with the
    cascade input's own term at the band's worst frequency for float32."""
    plan = plan_firmware(random_stable_model(seed, order, path="ff"), min_snr=-math.inf)
    fs = plan.realisation.fs
    fixed = noise.fixed_roundoff_terms(plan.cascade, plan.fixed, fs)
    assert noise.Q15_NOISE + sum(fixed) == pytest.approx(plan.predictions["q15"].roundoff_power, rel=1e-12)
    floating = noise.float32_roundoff_terms(plan.cascade, plan.floating, fs)
    assert len(floating) == len(plan.cascade.sections) and min(floating) >= 0.0
    total = plan.predictions["float"].roundoff_power
    assert 0.0 < sum(floating) <= total * (1.0 + 1e-12)
