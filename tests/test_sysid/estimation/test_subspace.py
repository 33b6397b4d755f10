"""The McKelvey-Akcay-Ljung frequency-domain subspace method."""

import numpy as np
import pytest

from sysid.core import lti
from sysid.core.errors import IdentificationError
from sysid.estimation.subspace import SubspaceDecomposition, stabilise, subspace_fit


def _fourth_order(rng):
    poles = np.array([0.95 * np.exp(0.3j), 0.95 * np.exp(-0.3j), 0.8 * np.exp(1.2j), 0.8 * np.exp(-1.2j)])
    A = lti.real_block_diagonal(poles)
    return A, rng.standard_normal((4, 1)), rng.standard_normal((1, 4)), np.array([[0.0]]), poles


def test_recovers_a_fourth_order_system_exactly_on_a_non_uniform_grid(rng):
    A, B, C, D, poles = _fourth_order(rng)
    omega = np.sort(rng.uniform(0.01, 2.5, 120))
    g = lti.frequency_response(A, B, C, D, np.exp(1j * omega))
    decomposition = SubspaceDecomposition(omega, g, q=10)
    s = decomposition.singular_values
    assert s[4] / s[3] < 1e-10  # the order is plain in the singular values
    fit = decomposition.fit(4)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(fit.A)), np.sort_complex(poles), atol=1e-10)
    check = np.sort(rng.uniform(0.0, np.pi, 50))
    np.testing.assert_allclose(lti.frequency_response(fit.A, fit.B, fit.C, fit.D, np.exp(1j * check)),
                               lti.frequency_response(A, B, C, D, np.exp(1j * check)), atol=1e-9)
    assert fit.stabilisation == "none"


def test_feedthrough_is_estimated_when_asked(rng):
    A, B, C, _, _ = _fourth_order(rng)
    omega = np.linspace(0.05, 3.0, 80)
    g = lti.frequency_response(A, B, C, 0.7, np.exp(1j * omega))
    fit = subspace_fit(omega, g, 4, q=10, feedthrough=True)
    assert fit.D[0, 0] == pytest.approx(0.7, abs=1e-9)


def test_unstable_poles_are_reflected_and_reported(rng):
    A = lti.real_block_diagonal(np.array([1.05 * np.exp(0.4j), 1.05 * np.exp(-0.4j), 0.5]))
    C = np.array([[1.0, 0.0, 1.0]])
    omega = np.linspace(0.05, 3.0, 80)
    g = lti.frequency_response(A, np.array([[1.0], [0.5], [0.2]]), C, 0.0, np.exp(1j * omega))
    fit = stabilise(A, C, omega, g, feedthrough=False, method="reflect")
    assert fit.stable and "reflected 2 pole(s)" in fit.stabilisation
    assert lti.spectral_radius(fit.A) == pytest.approx(1 / 1.05)
    kept = stabilise(A, C, omega, g, feedthrough=False, method="keep")
    assert not kept.stable and kept.stabilisation == "unstable (left as is)"
    with pytest.raises(IdentificationError, match="identified model is unstable"):
        stabilise(A, C, omega, g, feedthrough=False, method="reject")


def test_fit_if_stable_skips_unstable_orders(rng):
    A = lti.real_block_diagonal(np.array([1.02, 0.5]))
    omega = np.linspace(0.05, 3.0, 60)
    g = lti.frequency_response(A, np.ones((2, 1)), np.ones((1, 2)), 0.0, np.exp(1j * omega))
    decomposition = SubspaceDecomposition(omega, g, q=6)
    assert decomposition.fit_if_stable(2) is None
    assert decomposition.fit(2).stable


def test_bad_arguments_are_rejected():
    with pytest.raises(IdentificationError, match="1-D arrays of one length"):
        SubspaceDecomposition(np.arange(3.0), np.ones(4), q=2)
    with pytest.raises(IdentificationError, match="order must be between 1 and q-1"):
        SubspaceDecomposition(np.linspace(0.1, 1, 20), np.ones(20), q=5).fit(5)


@pytest.mark.parametrize("feedthrough", [False, True])
def test_fits_if_stable_batched_equals_one_by_one(rng, feedthrough):
    # Noisy responses of a fourth-order plant at several noise levels: at every order some fits
    # are stable and some not, as across the widths of the seed's grid.
    A, B, C, D, _ = _fourth_order(rng)
    omega = np.linspace(0.02, 2.5, 150)
    g = lti.frequency_response(A, B, C, 0.3 if feedthrough else 0.0, np.exp(1j * omega))
    decompositions = [SubspaceDecomposition(omega, g + level * (rng.standard_normal(g.size) + 1j * rng.standard_normal(g.size)),
                                            q=12, feedthrough=feedthrough) for level in (0.0, 1e-3, 1e-2, 0.1, 0.3)]
    seen = set()
    for n in range(1, 12):
        batched = SubspaceDecomposition.fits_if_stable(decompositions, n)
        for decomposition, fit in zip(decompositions, batched):
            single = decomposition.fit_if_stable(n)
            assert (fit is None) == (single is None)
            seen.add(fit is None)
            if fit is None:
                continue
            for name in "ABCD":
                np.testing.assert_allclose(getattr(fit, name), getattr(single, name), rtol=1e-7, atol=1e-9)
            check = np.exp(1j * np.linspace(0.0, np.pi, 40))
            np.testing.assert_allclose(lti.frequency_response(fit.A, fit.B, fit.C, fit.D, check),
                                       lti.frequency_response(single.A, single.B, single.C, single.D, check),
                                       rtol=1e-9, atol=1e-12)
    assert seen == {True, False}  # both stable and unstable candidates were compared
