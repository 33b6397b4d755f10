"""time-variation: inside the noise recording, and between recordings with the one that disagrees named."""

import pytest

from sysid.diagnose import diagnose, format_findings
from sysid.refine import refine_auto

from effect_sessions import TEST_REFIT, effect_case


@pytest.mark.parametrize("path, effect, odd", [("ff", "time-variation:3,200,1", "noise.wav"),
                                               ("fb", "time-variation:-3,200,2", "sweep2.wav")])
def test_a_change_between_recordings_names_the_recording(path, effect, odd):
    session, model = effect_case(path, 5, (effect,))
    findings = diagnose(model, session.noise, session.sweeps)
    top = findings.significant[0]
    assert top["effect"] == "time-variation", format_findings(findings)
    assert top["params"]["recording"] == odd
    assert odd not in top["params"]["agreeing"] and len(top["params"]["agreeing"]) == 2
    assert top["params"]["change_db"] == pytest.approx(abs(float(effect.split(":")[1].split(",")[0])), abs=1.0)


def test_a_change_inside_the_noise_recording_is_found():
    session, model = effect_case("ff", 5, ("time-variation:5",))
    assert diagnose(model, session.noise, session.sweeps).significant[0]["effect"] == "time-variation"


def test_auto_names_it_as_an_effect_that_cannot_be_modelled():
    session, model = effect_case("ff", 5, ("time-variation:3,200,1",))
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    assert "time-variation" in auto.stop_reason and "cannot be modelled" in auto.stop_reason
