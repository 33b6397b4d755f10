"""The seed's grid search over smoothing width and order (sysid.estimation.grid)."""

import numpy as np
from threadpoolctl import threadpool_limits

from conftest import short_spec
from effect_sessions import NOMINAL_ORDER

from sysid.core import lti
from sysid.core.thresholds import IDENTIFICATION_BAND
from sysid.estimation.grid import grid_search
from sysid.estimation.spectra import estimate_spectra, response, smooth_spectra
from sysid.estimation.subspace import SubspaceDecomposition
from sysid.simulate import simulate_session
from sysid.validation.sweeps import CompressedValidation, rms_from_responses, sweep_spectrum

GAMMAS = (10, 40, 160, 400, 1000)
ORDERS = tuple(range(1, 13))


def test_every_candidate_is_the_subspace_fit_of_its_width_and_order(sessions):
    # The grid batches the fits of one order over the widths; each entry must still be what one
    # decomposition of that width gives for that order, validated on the sweeps.
    session = sessions["fb"]
    spectra = estimate_spectra(session.noise.trimmed(3.0))
    sweeps = [sweep_spectrum(s) for s in session.sweeps]
    grid = grid_search(spectra, sweeps, IDENTIFICATION_BAND, GAMMAS, ORDERS)
    validation = CompressedValidation(sweeps)
    z = np.exp(2j * np.pi * validation.frequencies / spectra.fs)
    expected = np.full((len(GAMMAS), len(ORDERS)), np.nan)
    # One BLAS thread, as the grid runs: the high orders' fits amplify the round-off of a threaded
    # product to 1e-6 of the rms.
    with threadpool_limits(limits=1, user_api="blas"):
        for i, gamma in enumerate(GAMMAS):
            frf = response(smooth_spectra(spectra, gamma), IDENTIFICATION_BAND)
            decomposition = SubspaceDecomposition(2 * np.pi * frf.frequencies / spectra.fs, frf.g, q=30)
            for j, order in enumerate(ORDERS):
                fit = decomposition.fit_if_stable(order)
                if fit is not None:
                    expected[i, j] = validation.rms(lti.frequency_response(fit.A, fit.B, fit.C, fit.D, z))[0]
    assert np.array_equal(np.isnan(grid.rms), np.isnan(expected))
    assert np.isnan(expected).any() and np.isfinite(expected).sum() > 20  # both kinds of candidate occur
    np.testing.assert_allclose(grid.rms, expected, rtol=1e-9)
    # The choice: the best exact rms among the best compressed candidates.
    chosen = grid.chosen
    exact = rms_from_responses(sweeps, [lti.frequency_response(chosen.fit.A, chosen.fit.B, chosen.fit.C, chosen.fit.D,
                                                               np.exp(2j * np.pi * s.frequencies / s.fs)) for s in sweeps])
    assert chosen.rms == exact == min(c.rms for c in grid.best)
    assert np.nanmin(grid.rms) <= chosen.rms * 1.01



def test_where_no_candidate_is_stable_the_reflected_fits_are_ranked():
    """The seed's FB path at its nominal order on a short session whose clock drifts by -92 ppm: every fit of
    the grid has a pole outside the unit circle; the candidates are the fits with those poles reflected (all
    stable), not a refused session."""
    session = simulate_session(short_spec("fb", 31), effects=["clock-drift:-92.25"])
    spectra = estimate_spectra(session.noise.trimmed(3.0))
    sweeps = [sweep_spectrum(s) for s in session.sweeps]
    gammas, order = (100, 300, 500), NOMINAL_ORDER["fb"]
    with threadpool_limits(limits=1, user_api="blas"):
        responses = [response(smooth_spectra(spectra, gamma), IDENTIFICATION_BAND) for gamma in gammas]
        unstable = [SubspaceDecomposition(2 * np.pi * frf.frequencies / spectra.fs, frf.g, q=30).fit_if_stable(order)
                    for frf in responses]
    assert all(fit is None for fit in unstable)
    grid = grid_search(spectra, sweeps, IDENTIFICATION_BAND, gammas, (order,))
    assert grid.best and np.all(np.isfinite(grid.rms))
    for candidate in grid.best:
        assert np.max(np.abs(np.linalg.eigvals(candidate.fit.A))) < 1.0
