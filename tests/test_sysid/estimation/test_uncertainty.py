"""The 95 % frequency-response band (sysid.estimation.uncertainty) and its place in the model file."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import short_spec

from sysid.core.errors import ModelError
from sysid.core.model import Model
from sysid.core.plants import appendix_a_model
from sysid.estimation.output_error import refine_output_error
from sysid.estimation.uncertainty import delay_aligned_block, frequency_response_band
from sysid.random_plant import random_session
from sysid.simulate import simulate_session

COVERAGE_BAND = (20.0, 4000.0)
SHORT = dict(noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)


def _true_structure_fit(session, seconds=5.0, perturbation=0.0, seed=0):
    """Output-error fit at the true order and delay started from the true poles (moved by ``perturbation``): the converged model the band describes."""
    plant = session.plant
    body = session.noise.trimmed(3.0)
    data = delay_aligned_block(body, plant.delay, (20.0, 5000.0), seconds)
    rng = np.random.default_rng(seed)
    A = plant.A * (1 + perturbation * rng.uniform(-1, 1, plant.A.shape) * (plant.A != 0))
    A = A / max(1.0, 1.0001 * np.max(np.abs(np.linalg.eigvals(A))))
    fit = refine_output_error(A, plant.B, plant.C, plant.D, data, feedthrough=bool(plant.D[0, 0] != 0), max_iterations=80)
    model = Model(path=plant.path, fs=plant.fs, A=fit.A, B=fit.B, C=fit.C, D=fit.D, delay=plant.delay)
    return model, body, data


def _coverage(band, model, truth) -> float:
    f = band.frequencies_hz
    inside = (f >= COVERAGE_BAND[0]) & (f <= COVERAGE_BAND[1])
    return float(band.covers(truth.frequency_response(f), model.frequency_response(f))[inside].mean())


@pytest.fixture(scope="module")
def ff_case():
    session = simulate_session(short_spec("ff", seed=5))
    model, body, data = _true_structure_fit(session)
    return session, model, body, data


class TestFrequencyResponseBand:
    def test_covers_appendix_a_plant(self, ff_case):
        from sysid.estimation.spectra import estimate_spectra

        session, model, body, data = ff_case
        band = frequency_response_band(model, body, estimate_spectra(body), seconds=5.0)
        assert _coverage(band, model, session.plant) >= 0.9
        assert band.median_width < 0.05
        assert np.all(np.isfinite(band.relative_95)) and np.all(band.relative_95 >= 0)

    @pytest.mark.parametrize("seed", [3, 7, 12])
    def test_covers_random_plants(self, seed):
        from sysid.estimation.spectra import estimate_spectra

        session = random_session(seed, "fb", **SHORT)
        model, body, data = _true_structure_fit(session)
        band = frequency_response_band(model, body, estimate_spectra(body), seconds=5.0)
        assert _coverage(band, model, session.plant) >= 0.9
        assert band.median_width < 0.1

    @pytest.mark.parametrize("seed", [3, 12])
    def test_h1_leakage_is_not_read_as_model_bias(self, seed):
        # FB paths of random helmets 3 and 12 (lightly damped modes at low frequency): comparing the model's
        # response with H1 stated up to 46 (3) and 1.02 (12) times |H| at 20 Hz-1 kHz where the true
        # error is below 1.4 %; H1 against H1 of the model's own output states what is there.
        from sysid.estimation.spectra import estimate_spectra

        session = random_session(seed, "fb", **SHORT)
        model, body, data = _true_structure_fit(session, seed=seed)
        band = frequency_response_band(model, body, estimate_spectra(body), seconds=5.0)
        assert _coverage(band, model, session.plant) >= 0.9
        low = band.frequencies_hz <= 1000.0
        assert np.max(band.relative_95[low]) < 0.1
        assert band.median_width < 0.01

    def test_a_covariance_that_overflows_falls_back_to_the_h1_variance(self, ff_case, monkeypatch):
        # A pole at the unit circle makes the information matrix overflow; the band must stay
        # finite (a model carrying NaN cannot be saved) and still cover the truth.
        import dataclasses

        import sysid.estimation.uncertainty as uncertainty
        from sysid.estimation.spectra import estimate_spectra

        session, model, body, _ = ff_case
        exact = uncertainty.parameter_covariance

        def overflowed(core, data):
            lin = exact(core, data)
            return dataclasses.replace(lin, covariance=np.full_like(lin.covariance, np.nan))

        monkeypatch.setattr(uncertainty, "parameter_covariance", overflowed)
        band = frequency_response_band(model, body, estimate_spectra(body), seconds=5.0)
        assert np.all(np.isfinite(band.relative_95))
        assert "not finite (100 %)" in band.method
        assert _coverage(band, model, session.plant) >= 0.9
        model.uncertainty = band.to_dict()
        assert Model.from_dict(model.to_dict()).uncertainty is not None

    def test_variance_part_follows_square_root_law(self, ff_case):
        # Four times the data, half the scatter: the covariance scales as 1 / (number of bins).
        session, model, body, _ = ff_case
        short = frequency_response_band(model, body, seconds=1.25)
        long = frequency_response_band(model, body, seconds=5.0)
        ratio = np.median(short.variance_95 / long.variance_95)
        assert 1.6 < ratio < 2.5

    def test_under_modelled_model_is_widened(self, ff_case):
        # Dropping the weakest mode biases the model; the misfit to H1 must widen the band where it misses.
        from sysid.estimation.spectra import estimate_spectra

        session, model, body, data = ff_case
        from sysid.core.lti import block_output_row, real_block_diagonal

        poles = np.linalg.eigvals(model.A)
        upper = poles[poles.imag > 0]
        weakest = upper[np.argmin(np.abs(upper))]
        keep = poles[(np.abs(poles - weakest) > 1e-9) & (np.abs(poles - np.conj(weakest)) > 1e-9)]

        A = real_block_diagonal(keep)
        fit = refine_output_error(A, np.ones((A.shape[0], 1)), block_output_row(A), np.zeros((1, 1)), data, max_iterations=40)
        small = Model(path="ff", fs=model.fs, A=fit.A, B=fit.B, C=fit.C, D=fit.D)
        band = frequency_response_band(small, body, estimate_spectra(body), seconds=5.0)
        assert np.max(band.misfit) > 0
        assert "misfit" in band.method
        assert _coverage(band, small, session.plant) >= 0.9

    def test_without_spectra_gives_variance_only(self, ff_case):
        _, model, _, data = ff_case
        band = frequency_response_band(model, ff_case[2], band=(100.0, 1000.0), seconds=5.0)
        assert band.frequencies_hz[0] == 100.0 and band.frequencies_hz[-1] == 1000.0
        assert np.all(band.misfit == 0)
        np.testing.assert_allclose(band.relative_95, band.variance_95)


class TestInternals:
    def test_pole_jacobian_is_the_whole_models_central_difference(self, ff_case):
        # Only the moved pole's block changes; its difference must be the whole model's.
        from sysid.estimation.output_error import _params_to_poles, _poles_to_params, _Problem
        from sysid.estimation.uncertainty import _design, _pole_jacobian, _step

        _, model, _, data = ff_case
        params, pairs = _poles_to_params(np.linalg.eigvals(model.A))
        problem = _Problem(data, model.delay, feedthrough=bool(model.D[0, 0] != 0.0))
        theta = problem.linear(_params_to_poles(params, pairs))[2]
        idx = slice(0, 3000)
        jacobian = _pole_jacobian(problem, params, pairs, theta, idx)
        h = _step(params)
        scale = np.max(np.abs(_design(problem, _params_to_poles(params, pairs), idx) @ theta))
        for i in range(params.size):
            up, down = params.copy(), params.copy()
            up[i] += h[i]
            down[i] -= h[i]
            whole = (_design(problem, _params_to_poles(up, pairs), idx) @ theta
                     - _design(problem, _params_to_poles(down, pairs), idx) @ theta) / (2 * h[i])
            # The whole model's difference carries the round-off of the unmoved blocks, eps |model| / h.
            np.testing.assert_allclose(jacobian[:, i], whole, rtol=1e-7, atol=1e3 * np.finfo(float).eps * scale / h[i])

    @pytest.mark.parametrize("start, count", [(0, 5000), (123457, 3000), (7, 1)])
    def test_pole_powers_equal_direct_powers(self, start, count):
        from sysid.estimation.uncertainty import _pole_powers

        poles = np.array([0.9999 * np.exp(0.3j), 0.999999 * np.exp(0.001j), -0.5 + 0.1j, 0.97])
        t = np.arange(start, start + count)
        np.testing.assert_allclose(_pole_powers(poles, start, count), poles[None, :] ** t[:, None], rtol=1e-11, atol=1e-300)


class TestModelField:
    def _model(self):
        return appendix_a_model("ff")

    def test_round_trip(self, tmp_path):
        model = self._model()
        model.uncertainty = {"frequencies_hz": [20.0, 40.0, 60.0], "relative_95": [0.1, 0.02, 0.03], "method": "test"}
        path = tmp_path / "m.json"
        model.save(path)
        loaded = Model.load(path)
        assert loaded.uncertainty == model.uncertainty
        assert Model.from_dict(model.to_dict()).uncertainty == model.uncertainty

    def test_absent_is_none(self):
        data = self._model().to_dict()
        assert "uncertainty" not in data or data["uncertainty"] is None
        data.pop("uncertainty", None)
        assert Model.from_dict(data).uncertainty is None

    @pytest.mark.parametrize("value, message", [
        ({"frequencies_hz": [20.0, 40.0]}, "relative_95"),
        ({"frequencies_hz": [20.0, 40.0], "relative_95": [0.1]}, "same length"),
        ({"frequencies_hz": [40.0, 20.0], "relative_95": [0.1, 0.1]}, "increasing"),
        ({"frequencies_hz": [20.0, 40.0], "relative_95": [0.1, -0.1]}, "non-negative"),
        ({"frequencies_hz": [20.0, float("nan")], "relative_95": [0.1, 0.1]}, "finite"),
        ([1, 2], "object"),
    ])
    def test_bad_band_is_refused(self, value, message):
        data = self._model().to_dict()
        data["uncertainty"] = value
        with pytest.raises(ModelError, match=message):
            Model.from_dict(data)


@pytest.mark.slow
def test_coverage_over_many_random_plants():
    """Coverage >= 90 % on at least 90 % of 20 random plants (true-structure fits), median width < 5 %."""
    from sysid.estimation.spectra import estimate_spectra

    coverages, widths = [], []
    for seed in range(20):
        session = random_session(seed, "fb" if seed % 2 else "ff", **SHORT)
        model, body, data = _true_structure_fit(session, seed=seed)
        band = frequency_response_band(model, body, estimate_spectra(body), seconds=5.0)
        coverages.append(_coverage(band, model, session.plant))
        widths.append(band.median_width)
    assert np.mean(np.array(coverages) >= 0.9) >= 0.9
    assert np.median(widths) < 0.05
