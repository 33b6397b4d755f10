"""dc-offset: one algorithm; an ear offset becomes the model's output_offset, which compare accounts for."""

import numpy as np
import pytest
from effect_sessions import TEST_REFIT, effect_case

from sysid.core.model import Model
from sysid.diagnose import diagnose, format_findings
from sysid.io.data_quality import dc_offset
from sysid.refine import format_refinement, refine_auto
from sysid.validation.compare import compare


def test_dc_offset_is_the_median_of_part_means():
    x = 0.1 * np.random.default_rng(0).standard_normal(16000) + 0.01
    offset, significant = dc_offset(x)
    assert offset == pytest.approx(0.01, abs=2e-3) and significant
    assert not dc_offset(x - np.mean(x))[1]


@pytest.mark.parametrize("path, level", [("ff", 0.01), ("fb", -0.004)])
def test_ear_offset_is_found_and_taken_into_the_model(path, level, tmp_path):
    session, model = effect_case(path, 5, (f"dc-offset:{level}",))
    findings = diagnose(model, session.noise, session.sweeps)
    top = findings.significant[0]
    assert top["effect"] == "dc-offset", format_findings(findings)
    assert top["params"]["ear_offset_fs"] == pytest.approx(level, abs=5e-4)
    before = compare(model, session.sweeps)
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    assert auto.model.output_offset == pytest.approx(level, abs=5e-4), format_refinement(auto.steps)
    after = compare(auto.model, session.sweeps)
    assert after.rms_full < 0.5 * before.rms_full
    auto.model.save(tmp_path / "m.json")
    assert Model.load(tmp_path / "m.json").output_offset == auto.model.output_offset
    assert not diagnose(auto.model, session.noise, session.sweeps).significant


def test_an_input_offset_is_named_on_the_input_channel():
    session, model = effect_case("ff", 5, ("dc-offset:0.01,0",))
    top = diagnose(model, session.noise, session.sweeps).significant[0]
    assert top["effect"] == "dc-offset" and "input" in top["params"]["channel"]
    assert top["params"]["offset_fs"] == pytest.approx(0.01, abs=1e-3)


@pytest.mark.slow
def test_the_models_own_response_in_the_silence_is_no_ear_offset():
    """Clean random helmet 20 FB (a short session at the nominal order): the model's prediction rises by more
    than 1e-4 FS over the sweeps' leading silence (its gain below the sweeps' band on the input's microvolt
    mean) and the residual's mean, -1.03e-4 FS, drifts with it: no ear offset is named."""
    session, model = effect_case("fb", 20, ())
    found = next(f for f in diagnose(model, session.noise, session.sweeps) if f["effect"] == "dc-offset")
    assert not found["significant"], found["params"]
    assert abs(found["params"]["offset_fs"]) > 1e-4  # the residual's mean is there, only not an offset
