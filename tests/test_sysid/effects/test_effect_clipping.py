"""clipping: flat tops at any level on either channel are found, excluded, and the error falls."""

import numpy as np
import pytest
import scipy.signal
from effect_sessions import TEST_REFIT, effect_case

from sysid.diagnose import diagnose, format_findings
from sysid.io.clipping import clipped_stretches_of, ear_without_lines
from sysid.io.data_quality import clipped_against_prediction, clipped_samples, clipped_stretches
from sysid.io.lines import session_lines
from sysid.io.recordings import Recording
from sysid.refine import format_refinement, refine, refine_auto
from sysid.validation.compare import compare

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


def sweep_through(level, peak, seed, shape=lambda v: v):
    """(clean ear signal, its measured version): a tone whose amplitude rises to peak times the clip
    level through a low-pass path, clipped at level and with sensor noise of 0.7 % of the level added
    after the clipper (a preamplifier that flat-tops below full scale); ``shape`` bends the input."""
    t = np.arange(44100) / FS
    u = np.linspace(0.0, 1.0, t.size) * np.sin(2 * np.pi * 200 * t)
    path = [0.2], [1.0, -0.8]
    clean = scipy.signal.lfilter(*path, shape(u)) * peak * level / np.max(np.abs(scipy.signal.lfilter(*path, u)))
    noisy = np.clip(clean, -level, level) + 0.007 * level * np.random.default_rng(seed).standard_normal(t.size)
    return clean, np.round(noisy * 32768) / 32768


class TestClippedAgainstPrediction:
    def test_flat_tops_under_noise_that_the_histogram_misses_are_found(self):
        clean, x = sweep_through(0.12, 1.4, 4)
        assert clipped_samples(x).fraction == 0.0
        found = clipped_samples(x, predicted=clean)
        truth = np.abs(clean) >= 0.12
        assert found.fraction == pytest.approx(np.mean(truth), rel=0.25)
        assert np.all(found.mask[truth])
        assert len(found.levels) == 2 and all(abs(abs(v) - 0.12) < 0.002 for v in found.levels)

    def test_a_good_prediction_of_an_unclipped_signal_finds_nothing(self):
        clean, _ = sweep_through(0.12, 1.0, 5)
        x = clean + 0.007 * 0.12 * np.random.default_rng(5).standard_normal(clean.size)
        assert clipped_against_prediction(x, 1.01 * clean).fraction == 0.0

    @pytest.mark.parametrize("a2, a3", [(0.03, 0.0), (0.0, -0.05), (0.03, 0.1)])
    def test_an_input_nonlinearity_is_not_clipping(self, a2, a3):
        # The measured signal follows the input polynomial; the linear prediction is off at the peaks
        # by a few per cent, but the measured signal moves with it, it does not stay flat.
        measured, _ = sweep_through(0.5, 1.0, 6, shape=lambda v: v + a2 * v**2 + a3 * v**3)
        linear, _ = sweep_through(0.5, 1.0, 6)
        x = measured + 2e-4 * np.random.default_rng(6).standard_normal(measured.size)
        assert clipped_against_prediction(x, linear).fraction == 0.0
        assert clipped_samples(x, predicted=linear).fraction == 0.0


def hum(t, rng, level=1.2e-3, f0=50.0):
    """Mains hum of RMS level (FS) at f0 and its harmonics 2 and 3 at level/k, random phases."""
    return sum(np.sqrt(2) * level / k * np.sin(2 * np.pi * k * f0 * t + rng.uniform(0, 2 * np.pi)) for k in (1, 2, 3))


class TestClippedUnderAHum:
    # A preamplifier flat-topping at 0.18 FS, then mains hum of 1.2e-3 FS coupling in after it (2.1e-3 FS
    # peak, 1.2 % of the level, wider than the top bin): the tops are no longer flat.

    def recording(self, peak, seed, level=0.18):
        rng = np.random.default_rng(seed)
        clean, _ = sweep_through(level, peak, seed)
        t = np.arange(clean.size) / FS
        u = np.linspace(0.0, 1.0, t.size) * np.sin(2 * np.pi * 200 * t)
        y = np.clip(clean, -level, level) + hum(t, rng) + 1.5e-4 * rng.standard_normal(t.size)
        return Recording(u, np.round(y * 32768) / 32768, FS, "sweep1.wav"), clean

    def test_the_hum_hides_the_flat_tops_from_the_histogram_and_the_prediction(self):
        recording, clean = self.recording(1.3, 7)
        assert clipped_samples(recording.y).fraction == 0.0
        assert clipped_samples(recording.y, predicted=clean).fraction == 0.0

    def test_with_the_lines_taken_out_the_flat_tops_are_found_at_their_level(self):
        recording, clean = self.recording(1.3, 7)
        lines = session_lines([recording], [clean])
        # The hum's lines (gating by the loud samples, searched without, may add its sidebands).
        assert {50, 100, 150} <= {round(f) for f in lines}
        ear = ear_without_lines(recording, clean, lines)
        truth = np.abs(clean) >= 0.18
        # What is left is the clipped signal and the sensor noise: the flat tops within noise of 0.18.
        assert np.all(np.abs(np.abs(ear[truth]) - 0.18) < 1e-3)
        found = clipped_samples(ear, predicted=clean)
        assert found.fraction == pytest.approx(np.mean(truth), rel=0.25)
        assert np.mean(found.mask[truth]) > 0.95
        assert len(found.levels) == 2 and all(abs(abs(v) - 0.18) < 0.002 for v in found.levels)
        spans, fraction = clipped_stretches_of(recording, clean, lines)
        assert spans and fraction == pytest.approx(found.fraction)

    def test_an_unclipped_signal_under_a_hum_is_not_clipping(self):
        recording, clean = self.recording(0.95, 8)
        lines = session_lines([recording], [clean])
        assert clipped_samples(ear_without_lines(recording, clean, lines), predicted=clean).fraction == 0.0
        assert clipped_stretches_of(recording, clean, lines) == ([], 0.0)


def test_excluded_stretches_under_a_hum_leave_the_floor_as_it_is():
    # Two repeats of a sweep through a first-order path, clipped at 0.18 FS, each with a hum of its own
    # phase: the true path with its lines, the clipped stretches excluded, validates at the floor, and the
    # floor is the one of the same repeats unclipped (the excluded stretches add no hum to the difference).
    from sysid.core.model import Model
    t = np.arange(int(1.5 * FS)) / FS
    u = 0.5 * scipy.signal.chirp(t, 20.0, t[-1], 4000.0, method="logarithmic")
    a = 0.9
    model = Model(path="ff", fs=FS, A=np.array([[a]]), B=np.array([[1.0]]), C=np.array([[1 - a]]),
                  D=np.array([[0.0]]), disturbance_frequencies=[50.0, 100.0, 150.0])
    clean = model.simulate(u)
    peak = float(np.max(np.abs(clean)))

    def repeat(seed, level):
        rng = np.random.default_rng(seed)
        y = np.clip(clean / peak * 0.18 * 1.3, -level, level) + hum(t, rng) + 2e-4 * rng.standard_normal(t.size)
        return Recording(u, np.round(y * 32768) / 32768, FS, f"sweep{seed}.wav")

    clipped, unclipped = [repeat(k, 0.18) for k in (1, 2)], [repeat(k, 1.0) for k in (1, 2)]
    model.C = model.C * 0.18 * 1.3 / peak
    predictions = [model.simulate(r.u) for r in clipped]
    lines = session_lines(clipped, predictions)
    model.excluded = {r.path: clipped_stretches_of(r, p, lines)[0] for r, p in zip(clipped, predictions)}
    assert all(model.excluded.values())
    excluded, whole = compare(model, clipped), compare(Model(**{**model.__dict__, "excluded": {}}), unclipped)
    assert excluded.noise_floor == pytest.approx(whole.noise_floor, rel=0.1)
    assert excluded.ratio <= 1.2


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


@pytest.mark.slow
def test_a_preamplifier_clipping_below_full_scale_under_sensor_noise_is_found_in_the_users_workflow():
    # A random helmet whose ear preamplifier flat-tops at 0.12 FS, its sensor noise (0.7 % of the clip
    # level) after the clipper: the histogram sees 2.3x, not 6x; the model identified on the session
    # itself predicts beyond the flat tops, and the clipping is found, excluded, and the error falls.
    from sysid.identify import IdentificationOptions, identify
    from sysid.random_plant import random_session
    session = random_session(200, "ff", effects=["clipping:1.40,0.12"], noise_duration=8.0, sweep_duration=2.0,
                             sweep_silence=0.2)
    assert all(clipped_samples(s.y).fraction == 0.0 for s in session.sweeps)
    model = identify(session.noise, session.sweeps, "ff",
                     IdentificationOptions(gammas=tuple(range(10, 1001, 60)), refine_seconds=3.0)).model
    findings = diagnose(model, session.noise, session.sweeps)
    top = findings.significant[0]
    assert top["effect"] == "clipping", format_findings(findings)
    assert all(abs(abs(v) - 0.12) < 0.005 for v in top["params"]["levels_fs"]), format_findings(findings)
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    assert auto.steps[0].effect == "clipping" and auto.after.ratio <= 1.2, format_refinement(auto.steps, auto.stop_reason)
