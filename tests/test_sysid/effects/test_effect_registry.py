"""The registry of effects: every registered effect is complete and consistent, and every table reads it."""

import numpy as np
import pytest

from report.diagnosis_figures import FIGURE_KINDS, FINDING_PLOTS
from sysid import effects
from sysid.core.effect_spec import parse_effect
from sysid.core.errors import HelmetAncError
from sysid.diagnose import DETECTORS
from sysid.effects import Effect
from sysid.refine import NOT_REFINABLE, REFINE_EFFECTS, _correction_rank, parse_refinement
from sysid.simulate import SIMULATED_EFFECTS, random_effect

BUILT_IN = ["dc-offset", "clipping", "resonance", "highpass", "lowpass", "delay", "input-nonlinearity",
            "periodic-disturbance", "input-noise", "clock-drift", "time-variation", "reverberant-tail", "under-modelled"]


def test_the_built_in_effects_are_design_md_s_vocabulary():
    assert effects.names()[:len(BUILT_IN)] == BUILT_IN


@pytest.mark.parametrize("name", BUILT_IN)
def test_every_effect_is_complete(name):
    effect = effects.get(name)
    assert effect.summary and effect.detect is not None
    assert effect.figure in FIGURE_KINDS and name in FINDING_PLOTS
    if effect.refinable:
        assert name in REFINE_EFFECTS and effect.auto_params is not None
        parse_refinement(name)  # the defaults parse (parameters left at None are estimated)
    else:
        assert name in NOT_REFINABLE and effect.not_refinable
        with pytest.raises(HelmetAncError, match="not a model structure"):
            parse_refinement(name)
    if effect.simulated:
        assert name in SIMULATED_EFFECTS
        spec, parameter, value = random_effect(name, np.random.default_rng(1))
        parsed = parse_effect(spec, SIMULATED_EFFECTS)
        assert parsed.kind == name
        assert (parameter is None) == (value is None)


def test_detectors_run_after_what_they_need():
    order = list(DETECTORS)
    assert len(order) == len(set(order))
    position = {e.name: order.index(e.detect) for e in effects.effects()}
    for effect in effects.effects():
        for need in effect.needs:
            assert position[need] < position[effect.name] or effects.get(need).detect is effect.detect
        if effect.needs_all:
            # After every detector that reads only what it needs; among those that read every finding, under-modelled
            # (what nothing named explains) last.
            assert all(position[effect.name] > position[e.name] for e in effects.effects() if not e.needs_all)
    assert order[-1] is effects.get("under-modelled").detect


def test_registration_is_checked():
    with pytest.raises(HelmetAncError, match="registered already"):
        effects.register(Effect(name="delay", summary="another delay"))
    with pytest.raises(HelmetAncError, match="needs 'wobble'"):
        effects.register(Effect(name="x-test", summary="x", needs=("wobble",)))
    with pytest.raises(HelmetAncError, match="figure must be one of"):
        Effect(name="x-test", summary="x", figure="pie")
    with pytest.raises(HelmetAncError, match="unknown effect 'x-test'"):
        effects.get("x-test")
    with pytest.raises(HelmetAncError, match="time_base belongs to a data correction"):
        Effect(name="x-test", summary="x", time_base=True)


def test_a_time_base_correction_is_applied_before_the_others():
    # The clock resamples the ear signal the other corrections are read on (refine_corrections' order).
    corrections = [e for e in map(effects.get, effects.names()) if e.correct is not None]
    assert [e.name for e in corrections if e.time_base] == ["clock-drift"]
    specs = [parse_refinement(name) for name in ("dc-offset", "clipping", "clock-drift")]
    assert [s.kind for s in sorted(specs, key=_correction_rank)][0] == "clock-drift"


def test_registered_restores_the_registry():
    mine = Effect(name="x-test", summary="x", simulate_params=(), factor=lambda params, fs: ([1.0], [1.0]))
    with effects.registered(mine):
        assert "x-test" in SIMULATED_EFFECTS
    assert "x-test" not in SIMULATED_EFFECTS and "x-test" not in effects.names()
