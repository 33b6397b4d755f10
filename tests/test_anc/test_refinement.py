"""The effect loop through control: the attenuation a design on each model of a refinement history predicts
(anc.refinement), checked against the closed loop on the true plant."""

from __future__ import annotations

import numpy as np
import pytest
from effect_sessions import TEST_REFIT, effect_case

from anc.closed_loop import predicted_and_achieved
from anc.prediction import band_centres
from anc.refinement import attenuation_along, band_mean, step_label
from report.control_figures import refinement_table_html
from sysid.refine import refine

CENTRES = np.array(band_centres())
CHECKED = (CENTRES >= 50.0) & (CENTRES <= 1000.0)


@pytest.fixture(scope="module")
def delay_history():
    """A seed FB session whose path has 23 samples more delay than the nominal model knows, and the
    history: the nominal model, then the model after the delay refinement step."""
    session, model = effect_case("fb", 5, ("delay:23",))
    refined = refine(model, session.noise, session.sweeps, "delay", TEST_REFIT).model
    return session, [model, refined]


# A design takes minutes on a shared 2-core machine (anc.feedback's program): both checks that design are slow.
@pytest.mark.slow
def test_each_step_predicts_and_the_truth_agrees(delay_history):
    """The model that misses 23 samples of delay (about 600x its noise floor) states a wide band: the
    design on it is conservative and stable on the truth; after the delay step the band narrows, the
    design predicts more and the truth achieves what each step predicts (2 dB per band 50 Hz-1 kHz)."""
    session, models = delay_history
    steps = attenuation_along(models)
    assert [s.label for s in steps] == ["identified", "1. + delay"]
    assert steps[0].rms_ratio > 100 and steps[1].rms_ratio < 2
    means = []
    for step in steps:
        predicted, achieved = predicted_and_achieved(step.controller, session.plant, seconds=2.0, seed=1)
        error = np.abs(np.array(predicted["fb"]) - np.array(achieved["fb"]))
        assert np.max(error[CHECKED]) <= 2.0, f"{step.label}: achieved {np.max(error[CHECKED]):.2f} dB from predicted"
        means.append((band_mean(predicted["fb"]), band_mean(achieved["fb"])))
    assert means[1][0] > means[0][0] + 0.25, means
    assert means[1][1] > means[0][1] + 0.25, means
    table = refinement_table_html(steps, achieved=[m[1] for m in means])
    assert table.count("<tr>") == 3 and "1. + delay" in table


@pytest.mark.slow
def test_refused_model_is_recorded_not_raised():
    from sysid.core.model import Model
    from sysid.core.plants import appendix_a_model

    good = appendix_a_model("fb")
    unknown = Model.from_dict({**good.to_dict(), "identification": {"rms": 1e-2, "noise_floor": 1e-4}})
    steps = attenuation_along([unknown, good], labels=["poor", "good"])
    assert steps[0].controller is None and "noise floor" in steps[0].refused
    assert steps[1].controller is not None and step_label(good, 0) == "identified"
    assert "refused" in refinement_table_html(steps)
