"""resonance, highpass, lowpass: the family fit recovers a known factor behind the true plant."""

import pytest

from sysid import effects
from sysid.findings.dynamics import dynamics_findings, fit_factor

from effect_units import true_context


@pytest.mark.parametrize("spec, kind, name, value", [
    ("resonance:1000,6,8", "resonance", "f0_hz", 1000.0),
    ("highpass:60,1", "highpass", "corner_hz", 60.0),
    ("lowpass:2000,2", "lowpass", "corner_hz", 2000.0),
])
def test_the_fit_recovers_the_factor_and_only_its_family_is_significant(spec, kind, name, value):
    ctx = true_context("ff", 5, (spec,))
    fit = fit_factor(ctx, kind)
    assert fit.params[name] == pytest.approx(value, rel=0.02)
    assert fit.rms < 1.2 * ctx.comparison.noise_floor
    found = {f["effect"]: f for f in dynamics_findings(ctx)}
    assert [k for k, f in found.items() if f["significant"]] == [kind]


def test_nothing_on_the_true_plant():
    assert not any(f["significant"] for f in dynamics_findings(true_context("ff", 5, ())))


@pytest.mark.parametrize("kind", ["resonance", "highpass", "lowpass"])
def test_each_family_is_a_factor_in_series_with_one_shared_detector(kind):
    effect = effects.get(kind)
    b, a = effect.factor(dict(effect.simulate_params and {p.name: p.default for p in effect.simulate_params}), 44100.0)
    assert len(a) >= 2 and effect.detect is effects.get("resonance").detect
