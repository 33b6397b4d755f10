"""clock-drift: the direction is stated right, the ear channel is resampled by the ratio, the error falls."""

import numpy as np
import pytest
from effect_sessions import TEST_REFIT, effect_case, reference_case
from effect_units import true_session

from sysid.core.model import Model
from sysid.diagnose import diagnose, format_findings
from sysid.io.corrections import resample_ear
from sysid.refine import format_refinement, refine_auto
from sysid.refits import clock_residual
from sysid.validation.compare import compare


def test_resampling_undoes_a_fast_ear_clock():
    fs, ratio = 44100.0, 1 + 200e-6
    t_ear = np.arange(44100) / (fs * ratio)  # a fast ear clock samples the same sound more often
    tone = np.sin(2 * np.pi * 1000 * t_ear)
    corrected = resample_ear(tone, ratio)
    expected = np.sin(2 * np.pi * 1000 * np.arange(corrected.size) / fs)
    assert np.max(np.abs(corrected - expected)[10:-10]) < 1e-3


@pytest.mark.parametrize("ppm, word, case", [(50.0, "fast", effect_case), (-60.0, "slow", reference_case)])
def test_drift_is_found_with_its_sign_and_corrected(ppm, word, case, tmp_path):
    # Self-identified (the model from the drifting session itself), and a model from a clean session.
    session, model = case("ff", 5, (f"clock-drift:{ppm}",))
    findings = diagnose(model, session.noise, session.sweeps)
    top = findings.significant[0]
    assert top["effect"] == "clock-drift", format_findings(findings)
    assert top["params"]["ppm"] == pytest.approx(ppm, rel=0.1)
    assert f"runs {abs(top['params']['ppm']):.1f} ppm {word}" in top["explanation"]
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    assert auto.model.clock_ratio == pytest.approx(1 + ppm * 1e-6, abs=5e-6), format_refinement(auto.steps)
    assert compare(auto.model, session.sweeps).ratio <= 1.2, format_refinement(auto.steps, auto.stop_reason)
    auto.model.save(tmp_path / "m.json")
    again = Model.load(tmp_path / "m.json")
    assert compare(again, session.sweeps).rms == pytest.approx(compare(auto.model, session.sweeps).rms, rel=1e-9)


@pytest.mark.parametrize("error_ppm", [-1.0, 0.3])
def test_the_residual_reads_the_clock_ratio_to_hundredths_of_a_ppm(error_ppm):
    # The segments' phase slopes read a drift of a few ppm; the model's residual on the noise
    # recording refines the ratio further (a sharp mode needs it to a few 0.01 ppm).
    session = true_session("fb", 5, ("clock-drift:60",))
    model = Model.from_dict(session.truth["base_plant"])
    model.clock_ratio = 1 + (60 + error_ppm) * 1e-6
    delta = clock_residual(model, session.noise, 3.0)
    assert (model.clock_ratio * (1 + delta) - 1) * 1e6 == pytest.approx(60.0, abs=0.05)
