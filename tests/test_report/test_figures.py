"""Figure functions of report: each returns a Figure with the expected axes and data.

The checks read the plotted data back (lines, meshes, limits) rather than comparing
images; figures are never rendered here except where layout matters.
"""

import ast

import numpy as np
import pytest
from matplotlib.collections import QuadMesh
from matplotlib.figure import Figure
from repo import REPO

from report import figures
from report.diagnosis_figures import FINDING_PLOTS
from report.signals import instantaneous_frequency, min_max_envelope, worst_window
from report.style import db
from sysid.core.lti import hankel_singular_values
from sysid.core.model import Model
from sysid.core.sections import second_order_sections, sections_response
from sysid.estimation.spectra import response
from sysid.findings import DiagnosisContext
from sysid.validation.compare import compare


@pytest.fixture(scope="module")
def ff(sessions, identifications):
    session, result = sessions["ff"], identifications["ff"]
    return session, result, compare(result.model, session.sweeps)


def _main_axes(figure):
    """Axes that are not twins or colour bars (those have no own x label here)."""
    return [ax for ax in figure.axes if ax.get_label() != "<colorbar>"]


class TestIdentificationFigures:
    def test_averaged_spectra_two_channels_in_band(self, ff):
        session, _, _ = ff
        figure = figures.averaged_spectra_figure(session.noise)
        assert isinstance(figure, Figure) and len(figure.axes) == 2
        for ax in figure.axes:
            assert len(ax.get_lines()) == 2
            for line in ax.get_lines():
                f = line.get_xdata()
                assert f.min() >= 20.0 and f.max() <= 5000.0
        averaged = figure.axes[0].get_lines()[1]
        # The seed's grid: one point per fs / 2205 = 20 Hz.
        assert np.allclose(np.diff(averaged.get_xdata()), 20.0)

    def test_smoothed_estimates_one_curve_per_usable_gamma(self, ff):
        _, result, _ = ff
        figure = figures.smoothed_estimates_figure(result.spectra, gammas=(10, 100, 5000))
        magnitude, phase = figure.axes
        # gamma 5000 exceeds half the segment (1102 lags) and is dropped; plus the raw estimate.
        assert len(magnitude.get_lines()) == 3 and len(phase.get_lines()) == 3
        labels = [line.get_label() for line in magnitude.get_lines()]
        assert labels[1:] == ["smoothed, gamma = 10", "smoothed, gamma = 100"]
        raw = response(result.spectra, (20.0, 5000.0))
        assert np.allclose(magnitude.get_lines()[0].get_ydata(), db(raw.g))

    def test_singular_values_normalised_and_decreasing(self, ff):
        _, result, _ = ff
        figure = figures.singular_values_figure(result.grid.singular_values, chosen_order=5, count=3)
        (ax,) = figure.axes
        curves = [line for line in ax.get_lines() if line.get_label().startswith("gamma")]
        assert len(curves) == 3
        for line in curves:
            y = line.get_ydata()
            assert y[0] == pytest.approx(1.0) and np.all(np.diff(y) <= 1e-12)
        marker = [line for line in ax.get_lines() if "chosen order" in line.get_label()]
        assert marker and marker[0].get_xdata()[0] == pytest.approx(5.5)

    def test_order_singular_values_skips_too_wide_gammas(self, ff):
        _, result, _ = ff
        values = figures.order_singular_values(result.spectra, gammas=(50, 4000), q=20)
        assert list(values) == [50] and values[50].size == 20

    def test_heatmap_masks_unstable_and_marks_choice(self, ff):
        _, result, _ = ff
        grid = result.grid
        figure = figures.rms_heatmap_figure(grid, noise_floor=result.noise_floor)
        ax = figure.axes[0]
        mesh = next(c for c in ax.collections if isinstance(c, QuadMesh))
        shown = mesh.get_array()
        assert shown.shape == (grid.orders.size, grid.gammas.size)
        assert np.array_equal(np.ma.getmaskarray(shown), ~np.isfinite(grid.rms.T))
        finite = np.isfinite(grid.rms.T)
        assert np.allclose(shown[finite], grid.rms.T[finite] / result.noise_floor)
        star = next(line for line in ax.get_lines() if line.get_label().startswith("chosen"))
        assert (star.get_xdata()[0], star.get_ydata()[0]) == (grid.chosen.gamma, grid.chosen.order)


class TestModelFigures:
    def test_bode_model_curve_and_unwrapped_phase(self, ff):
        _, result, _ = ff
        figure = figures.model_bode_figure(result.model, result.spectra, gamma=result.grid.chosen.gamma,
                                           seed_model=result.seed_model)
        magnitude, phase = figure.axes
        model_line = next(line for line in magnitude.get_lines() if line.get_label().startswith("model"))
        f = model_line.get_xdata()
        assert f[0] == pytest.approx(20.0) and f[-1] == pytest.approx(5000.0)
        assert np.allclose(model_line.get_ydata(), db(result.model.frequency_response(f)))
        model_phase = phase.get_lines()[-1].get_ydata()
        assert np.max(np.abs(np.diff(model_phase))) < 180.0
        # Estimates are drawn on the model's branch: within 180 degrees of it everywhere.
        estimate = phase.get_lines()[0]
        reference = np.interp(estimate.get_xdata(), f, model_phase)
        assert np.all(np.abs(estimate.get_ydata() - reference) <= 180.0 + 1e-9)
        assert len(magnitude.get_lines()) == 4  # raw, smoothed, seed choice, model

    def test_pole_zero_marks_non_minimum_phase_zeros(self):
        # Zeros at 1.5 (outside) and 0.5 (inside), poles at 0.9 +- 0.1j.
        model = Model(path="fb", fs=44100.0, A=[[0.9, 0.1], [-0.1, 0.9]], B=[[1.0], [0.0]], C=[[1.0, 0.0]], D=[[1.0]])
        zeros = model.zeros()
        figure = figures.pole_zero_figure(model)
        assert len(figure.axes) == 2
        lines = {line.get_label(): line for line in figure.axes[0].get_lines()}
        assert len(lines["poles"].get_xdata()) == 2
        outside = lines.get("non-minimum-phase zeros (|z| > 1)")
        expected = int(np.sum(np.abs(zeros) > 1))
        assert (0 if outside is None else len(outside.get_xdata())) == expected
        if outside is not None:
            assert np.all(np.hypot(outside.get_xdata(), outside.get_ydata()) > 1.0)
        assert figure.axes[0].get_xlim()[1] >= max(1.15, np.max(np.abs(zeros)))

    def test_transient_decay_of_a_first_order_path(self):
        # h(k) = p^(k-1) for k >= 1: the envelope over the 10 ms before 3 s is p^(start - 1).
        p, fs = 0.9999, 44100.0
        model = Model(path="fb", fs=fs, A=[[p]], B=[[1.0]], C=[[1.0]], D=[[0.0]])
        start = int(3.0 * fs) - int(0.01 * fs)
        assert figures.transient_decay_db(model, 3.0) == pytest.approx(20 * np.log10(p) * (start - 1), abs=1e-6)

    def test_impulse_response_panels(self, ff):
        _, result, _ = ff
        figure = figures.impulse_response_figure(result.model, transient_s=1.0, short_ms=4.0)
        short, long = figure.axes
        t = short.get_lines()[0].get_xdata()
        assert t[0] == 0.0 and t[-1] < 4.0
        envelope = long.get_lines()[0]
        assert envelope.get_xdata()[-1] <= 1.2 and np.nanmax(envelope.get_ydata()) == pytest.approx(0.0, abs=1e-9)
        assert any(line.get_xdata()[0] == 1.0 for line in long.get_lines() if len(line.get_xdata()) == 2)


class TestValidationFigures:
    def test_sweep_prediction_zooms_on_the_largest_error(self, ff):
        _, _, comparison = ff
        record = comparison.per_sweep[0]
        figure = figures.sweep_prediction_figure(record, zoom_s=0.02)
        assert len(figure.axes) == 6  # three panels, each with a twin axis
        zoom = figure.axes[2]
        low, high = zoom.get_xlim()
        assert high - low == pytest.approx(0.02, abs=2 / record["fs"])
        start, stop = worst_window(record["residual"], record["fs"], 0.02)
        assert low == pytest.approx(start / record["fs"]) and high == pytest.approx((stop - 1) / record["fs"])

    def test_error_bands_steps_match_the_table(self, ff):
        _, _, comparison = ff
        figure = figures.error_bands_figure(comparison)
        levels, ratio = figure.axes
        error = levels.get_lines()[0]
        assert len(error.get_xdata()) == len(comparison.bands) + 1
        assert np.allclose(error.get_ydata()[:-1], db([b["error_rms"] for b in comparison.bands]))
        assert np.allclose(ratio.get_lines()[0].get_ydata()[:-1], db([b["ratio"] for b in comparison.bands]))

    def test_residual_correlation_flags_points_outside_the_bound(self, ff):
        _, _, comparison = ff
        figure = figures.residual_correlation_figure(comparison)
        auto, cross = figure.axes
        flagged = next(line for line in cross.get_lines() if line.get_label() == "outside the 99 % bound")
        outside = np.abs(comparison.residual_input_crosscorrelation) > comparison.crosscorrelation_bound
        assert len(flagged.get_xdata()) == int(outside.sum())
        flagged_auto = next(line for line in auto.get_lines() if line.get_label() == "outside the 99 % bound")
        r = comparison.residual_autocorrelation[1:]
        assert len(flagged_auto.get_xdata()) == int(np.sum(np.abs(r) > comparison.autocorrelation_bound))

    def test_coherence_within_unit_interval(self, ff):
        _, result, _ = ff
        figure = figures.coherence_figure(result.spectra)
        coherence = figure.axes[0].get_lines()[0].get_ydata()
        assert np.all((coherence >= 0) & (coherence <= 1)) and np.median(coherence) > 0.9


def _finding(effect, **params):
    return {"effect": effect, "significant": True, "score": 2.0, "params": params, "explanation": "test",
            "remedy": "none", "evidence": {}}


class TestDiagnosisFigures:
    @pytest.mark.parametrize("finding", [
        _finding("delay", samples=3),
        _finding("input-nonlinearity", a2=0.1, a3=0.0),
        _finding("periodic-disturbance", frequencies_hz=[50.0, 150.0]),
        _finding("input-noise", input_snr_db=10.0),
        _finding("dc-offset", offset_fs=0.01),
        _finding("clipping", fraction=0.01),
        _finding("time-variation", change_db=1.0),
        dict(_finding("clock-drift", ppm=50.0), evidence={"segment_delays": [0.0, -0.3, -0.6, -0.9]}),
        _finding("resonance", f0_hz=3400.0, q=8.0, gain_db=10.0),
        _finding("highpass", corner_hz=60.0, order=1),
        _finding("lowpass", corner_hz=2500.0, order=2),
        _finding("under-modelled", order=5, worst_band_hz=800.0),
        _finding("reverberant-tail", length_ms=30.0, states=40, start_ms=2.0),
    ], ids=lambda f: f["effect"])
    def test_each_effect_gets_a_plot(self, ff, finding):
        session, result, comparison = ff
        context = DiagnosisContext(result.model, session.noise, session.sweeps, comparison)
        figure = figures.finding_figure(finding, context, result.spectra)
        assert isinstance(figure, Figure)
        assert finding["effect"] in figure.axes[0].get_title()

    def test_disturbance_lines_are_marked(self, ff):
        session, result, comparison = ff
        context = DiagnosisContext(result.model, session.noise, session.sweeps, comparison)
        figure = figures.finding_figure(_finding("periodic-disturbance", frequencies_hz=[50.0, 150.0]), context,
                                        result.spectra)
        marks = [line.get_xdata()[0] for line in figure.axes[0].get_lines() if line.get_linestyle() == "--"]
        assert marks == [50.0, 150.0]

    def test_series_factor_is_drawn_over_the_mismatch(self, ff):
        session, result, comparison = ff
        context = DiagnosisContext(result.model, session.noise, session.sweeps, comparison)
        figure = figures.finding_figure(_finding("resonance", f0_hz=1000.0, q=5.0, gain_db=10.0), context, result.spectra)
        fitted = next(line for line in figure.axes[0].get_lines() if "factor" in str(line.get_label()))
        assert np.max(fitted.get_ydata()) == pytest.approx(10.0, abs=0.1)

    def test_the_delay_scan_is_drawn_from_the_context(self, ff):
        session, result, comparison = ff
        context = DiagnosisContext(result.model, session.noise, session.sweeps, comparison)
        costs = np.full(result.model.delay + 40, np.nan)
        costs[::2] = np.linspace(4.0, 2.0, costs[::2].size)
        costs[30] = 1.0
        context.values["delay-scan"] = (30, costs)
        figure = figures.finding_figure(_finding("delay", samples=30 - result.model.delay), context, result.spectra)
        scan = figure.axes[0].get_lines()[0]
        # The evaluated delays only, each cost over the least.
        np.testing.assert_array_equal(scan.get_xdata(), np.flatnonzero(np.isfinite(costs)))
        np.testing.assert_allclose(scan.get_ydata(), costs[np.isfinite(costs)])
        star = next(line for line in figure.axes[0].get_lines() if line.get_marker() == "*")
        assert list(star.get_xdata()) == [30]

    def test_the_segments_are_drawn_from_the_context(self, ff):
        session, result, comparison = ff
        context = DiagnosisContext(result.model, session.noise, session.sweeps, comparison)
        f = np.linspace(0.0, 22050.0, 2206)
        responses = np.array([np.full(f.size, 2.0 + k) for k in range(4)])
        context.values["segments"] = (f, responses, np.ones((4, f.size)), np.arange(4) * 44100.0 + 22050.0)
        finding = dict(_finding("clock-drift", ppm=0.0), evidence={"segment_delays": [0.0, 0.1, 0.2, 0.3]})
        figure = figures.finding_figure(finding, context, result.spectra)
        levels = [line.get_ydata()[0] for line in figure.axes[0].get_lines()]
        assert levels == pytest.approx(list(20 * np.log10(2.0 + np.arange(4))))

    def test_the_tail_is_drawn_from_the_context(self, ff):
        from sysid.findings.tail import LongResponse

        session, result, comparison = ff
        context = DiagnosisContext(result.model, session.noise, session.sweeps, comparison)
        fs, noise = session.noise.fs, 1e-6
        decay = np.exp(-np.arange(441) / 44.1)
        envelope = noise**2 * (1.0 + 1e8 * decay)
        context.values["long-response"] = LongResponse(fs, 0, None, np.zeros(441), np.zeros(441), noise, envelope,
                                                       envelope / 10, envelope / 100, 0.0075, 0.006, 0.005, True)
        figure = figures.finding_figure(_finding("reverberant-tail", length_ms=7.5, states=40, start_ms=1.0), context,
                                        result.spectra)
        data = figure.axes[0].get_lines()[0]
        # dB over the estimate's noise against ms from the input, the length marked.
        np.testing.assert_allclose(data.get_ydata(), 10 * np.log10(envelope / noise**2))
        assert data.get_xdata()[-1] == pytest.approx(1e3 * 440 / fs)
        mark = next(line for line in figure.axes[0].get_lines() if "7.5 ms" in str(line.get_label()))
        assert list(mark.get_xdata()) == [7.5, 7.5]

    def test_no_figure_module_runs_a_detector(self):
        for path in (REPO / "report").glob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom) and node.module:
                    assert node.module not in ("sysid.findings.delay", "sysid.findings.variation"), path.name

    def test_dedicated_plots_cover_the_detectors(self):
        from sysid.diagnose import DETECTORS

        names = {"dc_offset_finding": "dc-offset", "clipping_finding": "clipping", "delay_finding": "delay",
                 "nonlinearity_finding": "input-nonlinearity", "disturbance_finding": "periodic-disturbance",
                 "input_noise_finding": "input-noise", "clock_drift_finding": "clock-drift",
                 "time_variation_finding": "time-variation", "dynamics_findings": ("resonance", "highpass", "lowpass"),
                 "tail_finding": "reverberant-tail", "under_modelled_finding": "under-modelled"}
        effects = set()
        for detector in DETECTORS:
            named = names[detector.__name__]
            effects.update((named,) if isinstance(named, str) else named)
        assert effects <= set(FINDING_PLOTS)

    def test_refinement_staircase(self):
        history = [{"effect": "delay", "params": {"samples": 23}, "rms_before": 8e-4, "rms_after": 2e-4},
                   {"effect": "periodic-disturbance", "params": {}, "rms_before": 2e-4, "rms_after": 1.1e-4}]
        figure = figures.refinement_figure(history, noise_floor=1e-4)
        (ax,) = figure.axes
        points = next(line for line in ax.get_lines() if line.get_marker() == "o")
        assert np.allclose(points.get_ydata(), [8e-4, 2e-4, 1.1e-4])
        assert [t.get_text() for t in ax.get_xticklabels()] == ["identified", "+ delay", "+ periodic-disturbance"]
        assert ax.get_yscale() == "log" and ax.get_ylim()[0] < 1e-4
        floor = next(line for line in ax.get_lines() if line.get_label().startswith("noise floor"))
        assert np.allclose(floor.get_ydata(), 1e-4)
        # Removing a disturbance lowers the floor too: it is drawn per step when the history has it.
        history[1].update(noise_floor_before=1e-4, noise_floor_after=0.8e-4)
        history[0].update(noise_floor_before=1e-4, noise_floor_after=1e-4)
        stepped = figures.refinement_figure(history, noise_floor=0.8e-4)
        floor = next(line for line in stepped.axes[0].get_lines() if line.get_label().startswith("noise floor"))
        assert np.allclose(floor.get_ydata(), [1e-4, 1e-4, 0.8e-4, 0.8e-4])
        labels = [t.get_text() for t in stepped.axes[0].texts]
        assert labels == ["8.00x", "2.00x", "1.38x"]
        empty = figures.refinement_figure([], noise_floor=1e-4, current_rms=3e-4)
        assert np.allclose(next(line for line in empty.axes[0].get_lines() if line.get_marker() == "o").get_ydata(), [3e-4])


class TestSignals:
    def test_instantaneous_frequency_of_a_linear_chirp(self):
        fs = 8000.0
        t = np.arange(int(fs)) / fs
        u = np.sin(2 * np.pi * (100 * t + 0.5 * 400 * t**2))  # 100 -> 500 Hz in 1 s
        f = instantaneous_frequency(u, fs)
        middle = slice(1000, 7000)
        assert np.nanmax(np.abs(f[middle] - (100 + 400 * t[middle]))) < 5.0

    def test_silence_is_nan(self):
        fs = 8000.0
        u = np.concatenate([np.zeros(2000), np.sin(2 * np.pi * 200 * np.arange(4000) / fs), np.zeros(2000)])
        f = instantaneous_frequency(u, fs)
        assert np.all(np.isnan(f[:1500])) and np.nanmedian(f[3000:5000]) == pytest.approx(200.0, abs=1.0)

    def test_min_max_envelope_keeps_extremes(self, rng):
        x = rng.standard_normal(100_000)
        t = np.arange(x.size)
        t_out, x_out = min_max_envelope(t, x, columns=500)
        assert x_out.size == 1000 and x_out.max() == x.max() and x_out.min() == x.min()
        assert np.all(np.diff(t_out) >= 0)


def _random_stable_model(rng, order, feedthrough, delay=0):
    poles = rng.uniform(0.5, 0.99, order // 2) * np.exp(1j * rng.uniform(0.01, 3.0, order // 2))
    A = np.zeros((order, order))
    for k, p in enumerate(poles):
        A[2 * k:2 * k + 2, 2 * k:2 * k + 2] = [[p.real, p.imag], [-p.imag, p.real]]
    if order % 2:
        A[-1, -1] = 0.7
    return Model(path="fb", fs=44100.0, A=A, B=rng.standard_normal((order, 1)), C=rng.standard_normal((1, order)),
                 D=[[rng.standard_normal() if feedthrough else 0.0]], delay=delay)


class TestSections:
    @pytest.mark.parametrize("order,feedthrough,delay", [(7, False, 0), (6, True, 0), (5, False, 4), (1, False, 0)])
    def test_sections_reproduce_the_impulse_response(self, rng, order, feedthrough, delay):
        import scipy.signal

        model = _random_stable_model(rng, order, feedthrough, delay)
        sections = second_order_sections(model)
        assert len(sections) == (order + 1) // 2
        impulse = np.zeros(400)
        impulse[0] = 1.0
        sos = np.array([[*s.b, *s.a] for s in sections])
        h = scipy.signal.sosfilt(sos, impulse)
        h = np.concatenate([np.zeros(delay), h[: impulse.size - delay]])
        expected = model.simulate(impulse)
        # Relative degree kept: without D the first sample is exactly zero, no advance.
        assert np.allclose(h, expected, atol=1e-9 * np.max(np.abs(expected)))
        if not feedthrough:
            assert any(s.b[0] == 0.0 for s in sections) and h[0] == 0.0

    def test_poles_closest_to_the_circle_come_last(self, identifications):
        model = identifications["ff"].model
        radii = [max(abs(p) for p in s.poles) for s in second_order_sections(model)]
        assert radii == sorted(radii)
        f = np.linspace(20, 20000, 300)
        assert np.allclose(sections_response(second_order_sections(model), f, model.fs), model.frequency_response(f),
                           rtol=1e-8)

    def test_hankel_singular_values_of_a_first_order_system(self):
        a, b, c = 0.8, 2.0, 0.5
        model = Model(path="fb", fs=44100.0, A=[[a]], B=[[b]], C=[[c]], D=[[0.0]])
        assert hankel_singular_values(model.A, model.B, model.C) == pytest.approx([abs(b * c) / (1 - a * a)])

    def test_hankel_needs_a_stable_model(self):
        model = Model(path="fb", fs=44100.0, A=[[1.2]], B=[[1.0]], C=[[1.0]], D=[[0.0]])
        with pytest.raises(ValueError, match="stable"):
            hankel_singular_values(model.A, model.B, model.C)
