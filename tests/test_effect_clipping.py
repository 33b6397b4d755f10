"""clipping: flat tops at any level on either channel are found, excluded, and the error falls."""

import numpy as np
import pytest

from sysid.compare import compare
from sysid.data_quality import clipped_samples, clipped_stretches
from sysid.diagnose import diagnose, format_findings
from sysid.refine import format_refinement, refine, refine_auto

from effect_sessions import TEST_REFIT, effect_case

FS = 44100.0


class TestClippedSamples:
    def test_a_sine_peak_is_not_clipping(self):
        t = np.arange(44100) / FS
        x = np.round(0.5 * np.sin(2 * np.pi * 50 * t) * 32768) / 32768
        assert clipped_samples(x).fraction == 0.0

    def test_noise_is_not_clipping(self):
        x = 0.1 * np.random.default_rng(1).standard_normal(100000)
        assert clipped_samples(x).fraction == 0.0

    @pytest.mark.parametrize("level", [0.05, 0.3, 0.9])
    def test_flat_tops_below_full_scale_are_found_at_their_level(self, level):
        t = np.arange(44100) / FS
        clean = np.sin(2 * np.pi * 50 * t)
        x = np.clip(clean, -level, level) + 2e-4 * np.random.default_rng(2).standard_normal(t.size)
        found = clipped_samples(x)
        truth = np.abs(clean) >= level
        assert found.fraction == pytest.approx(np.mean(truth), rel=0.1)
        assert found.levels and all(abs(abs(v) - level) < 0.01 * level + 1e-3 for v in found.levels)

    def test_samples_at_the_rails_count_whatever_the_histogram(self):
        x = 0.1 * np.random.default_rng(3).standard_normal(10000)
        x[100:105] = 32767 / 32768
        assert clipped_samples(x).fraction == pytest.approx(5 / 10000)

    def test_stretches_are_widened_and_merged(self):
        mask = np.zeros(1000, bool)
        mask[100:110] = mask[115:120] = True
        assert clipped_stretches(mask, 1000.0, 0.01) == [[0.09, 0.13]]


@pytest.mark.parametrize("path, effect", [("ff", "clipping:1.3"), ("ff", "clipping:1.5,0.3")])
def test_clipping_is_found_and_excluded_until_the_floor(path, effect):
    session, model = effect_case(path, 5, (effect,))
    findings = diagnose(model, session.noise, session.sweeps)
    top = findings.significant[0]
    assert top["effect"] == "clipping", format_findings(findings)
    assert top["params"]["fraction"] == pytest.approx(max(s.clipped_fraction[1] for s in session.sweeps), rel=0.2)
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    assert auto.steps[0].effect == "clipping" and auto.steps[0].accepted, format_refinement(auto.steps)
    assert set(auto.model.excluded) >= {"sweep1.wav", "sweep2.wav"}
    assert compare(auto.model, session.sweeps).ratio <= 1.2, format_refinement(auto.steps, auto.stop_reason)


def test_refine_add_clipping_reports_the_excluded_fraction():
    session, model = effect_case("ff", 5, ("clipping:1.5,0.3",))
    result = refine(model, session.noise, session.sweeps, "clipping", TEST_REFIT)
    fractions = result.step.params["excluded_fraction"]
    assert len(fractions) == 3 and all(0.0 <= f < 0.5 for f in fractions) and max(fractions) > 0.0
    assert result.after.excluded_fraction > 0.0
    assert result.after.rms < result.before.rms
