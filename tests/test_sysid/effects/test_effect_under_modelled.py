"""under-modelled: above twice the noise floor, diagnose never answers "nothing significant"."""

import copy

import pytest

from sysid.diagnose import diagnose, format_findings
from sysid.identify import IdentificationOptions, identify
from sysid.refine import format_refinement, refine_auto
from sysid.simulate import simulate_session

from conftest import short_spec
from effect_sessions import TEST_REFIT


@pytest.mark.parametrize("path, order", [("ff", 2), ("fb", 3), ("ff", 3)])
def test_a_too_low_order_is_never_nothing(path, order):
    session = simulate_session(short_spec(path, 9))
    model = identify(session.noise, session.sweeps, path,
                     IdentificationOptions(gammas=(100, 300), orders=(order,), refine_seconds=2.0)).model
    findings = diagnose(model, session.noise, session.sweeps)
    assert findings.comparison.ratio > 2.0
    assert findings.significant, format_findings(findings)
    under = next(f for f in findings if f["effect"] == "under-modelled")
    if findings.significant[0]["effect"] == "under-modelled":
        assert under["params"]["suggested_order"] == order + 2
        assert under["params"]["bands_hz"] and "order" in under["explanation"]


def test_more_order_brings_a_too_low_order_to_the_floor():
    session = simulate_session(short_spec("ff", 9))
    model = identify(session.noise, session.sweeps, "ff",
                     IdentificationOptions(gammas=(100, 300), orders=(3,), refine_seconds=2.0)).model
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    assert auto.after.ratio <= 1.2, format_refinement(auto.steps, auto.stop_reason)
    assert auto.stop_reason.startswith("at the floor")


def test_an_error_more_order_does_not_lower_is_not_called_a_too_low_order():
    # The true plant with a 0.06 % gain error: above the floor, under twice it, and no mode helps.
    session = simulate_session(short_spec("ff", 9))
    model = copy.deepcopy(session.plant)
    model.C = model.C * 1.0006
    findings = diagnose(model, session.noise, session.sweeps)
    assert 1.2 < findings.comparison.ratio < 2.0
    under = next(f for f in findings if f["effect"] == "under-modelled")
    assert not under["significant"]
    assert "is not what the model lacks" in under["explanation"] and "too low" not in under["explanation"]
