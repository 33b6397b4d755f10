"""References ``package.module:attribute`` to an effect's functions, resolved when first read."""

import pytest

from sysid import effects
from sysid.core.errors import HelmetAncError
from sysid.effects import Effect
from sysid.effects.references import resolve
from sysid.findings import finding

FUNCTIONS = ("detect", "build", "complete", "correct", "auto_params", "factor", "random")


def _detect(ctx):
    return finding("x-test", False, 0.0, {}, "never significant", "none")


class TestResolve:
    def test_a_reference_names_the_function(self):
        assert resolve("sysid.effects.references:resolve") is resolve
        assert resolve("sysid.effects:Effect.has") is Effect.has

    def test_a_callable_or_none_is_taken_as_it_is(self):
        assert resolve(_detect) is _detect and resolve(None) is None

    @pytest.mark.parametrize("text", ["sysid.refits.add_delay", ":add_delay", "sysid.refits:"])
    def test_a_malformed_reference_is_refused(self, text):
        with pytest.raises(HelmetAncError, match="expected 'package.module:attribute'"):
            resolve(text)

    def test_a_missing_attribute_is_named(self):
        with pytest.raises(HelmetAncError, match="sysid.refits has no attribute 'add_wobble'"):
            resolve("sysid.refits:add_wobble")

    def test_a_reference_to_a_value_is_refused(self):
        with pytest.raises(HelmetAncError, match="not a callable"):
            resolve("sysid.core.thresholds:EXCESS")


class TestEffectFields:
    def test_a_reference_is_resolved_when_read_and_kept(self):
        effect = Effect(name="x-test", summary="x", detect="test_effect_references:_detect")
        assert effect.has("detect") and effect.__dict__["detect"] == "test_effect_references:_detect"
        assert effect.detect is _detect and effect.__dict__["detect"] is _detect

    def test_a_wrong_reference_fails_when_read_not_when_given(self):
        effect = Effect(name="x-test", summary="x", detect="test_effect_references:_wobble")
        assert effect.has("detect") and not effect.has("build")
        with pytest.raises(HelmetAncError, match="no attribute '_wobble'"):
            effect.detect

    def test_neither_callable_nor_reference_is_refused(self):
        with pytest.raises(HelmetAncError, match="detect must be a callable or a reference"):
            Effect(name="x-test", summary="x", detect=3)

    def test_the_checks_read_references_without_resolving_them(self):
        with pytest.raises(HelmetAncError, match="only a correction"):
            Effect(name="x-test", summary="x", correct="nowhere.at_all:correct")
        structure = Effect(name="x-test", summary="x", refine_params=(), build="nowhere.at_all:build")
        assert structure.refinable

    def test_a_registered_reference_joins_the_detectors(self):
        with effects.registered(Effect(name="x-test", summary="x", detect="test_effect_references:_detect")):
            assert _detect in effects.detector_order()
            assert effects.findings_read_by(_detect) == ()
        assert _detect not in effects.detector_order()


def test_every_reference_names_a_function():
    for effect in effects.effects():
        for field in FUNCTIONS:
            if effect.has(field):
                assert callable(getattr(effect, field)), (effect.name, field)
        # The shared values a detector reads are declared on the function the reference names.
        assert isinstance(getattr(effect.detect, "uses", ()), tuple), effect.name
