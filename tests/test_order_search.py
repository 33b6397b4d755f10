"""Models out of the order search's output-error fits are balanced (sysid.order_search, sysid.output_error).

The order search refines starts built from poles of neighbouring orders; two poles can
land almost on one another, and the modal form with a unit output row then holds the
response only through huge, cancelling entries of B (1e9-1e12 on random helmets), above
the model file's limit (``sysid.model.MAX_COEFFICIENT``): identify used to raise there.
"""

import numpy as np
import pytest

from sysid import lti
from sysid.model import MAX_COEFFICIENT, Model
from sysid.output_error import block_data, refine_output_error
from sysid.recordings import Recording

FS = 44100.0
Z = np.exp(1j * np.linspace(0.01, 3.0, 200))
# A double pole at 0.9 (two equal roll-off corners give one): G(z) = 1 / (z - 0.9)^2.
A_TRUE = np.array([[0.9, 1.0], [0.0, 0.9]])
B_TRUE = np.array([[0.0], [1.0]])
C_TRUE = np.array([[1.0, 0.0]])


def _data():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(int(FS))
    y = lti.simulate(A_TRUE, B_TRUE, C_TRUE, 0.0, u) + 1e-4 * rng.standard_normal(u.size)
    return block_data(Recording(u, y, FS), (20.0, 20000.0), 1.0)


@pytest.mark.parametrize("gap", [1e-6, 1e-4])
def test_fit_with_nearly_coincident_poles_is_balanced(gap):
    # Held at poles 0.9 and 0.9 + gap (one iteration), the modal B is about 1 / gap.
    start = lti.real_block_diagonal(np.array([0.9, 0.9 + gap]))
    fit = refine_output_error(start, np.zeros((2, 1)), np.zeros((1, 2)), np.zeros((1, 1)), _data(), max_iterations=1)
    assert max(np.abs(fit.A).max(), np.abs(fit.B).max(), np.abs(fit.C).max()) < 10.0
    truth = lti.frequency_response(A_TRUE, B_TRUE, C_TRUE, 0.0, Z)
    assert np.max(np.abs(lti.frequency_response(fit.A, fit.B, fit.C, fit.D, Z) - truth)) < 1e-3 * np.max(np.abs(truth))
    # Both Gramians equal and diagonal: the balanced realisation.
    wc, wo = lti.gramians(fit.A, fit.B, fit.C)
    assert np.max(np.abs(wc - wo)) < 1e-6 * np.max(np.abs(wc))
    Model(path="fb", fs=FS, A=fit.A, B=fit.B, C=fit.C, D=fit.D)


def test_fit_too_close_to_balance_is_still_within_the_model_limit():
    # At a gap of 1e-9 the modal B is 1e9 and the Gramians are lost to round-off; the
    # diagonal equalisation still brings the entries to about 3e4.
    start = lti.real_block_diagonal(np.array([0.9, 0.9 + 1e-9]))
    fit = refine_output_error(start, np.zeros((2, 1)), np.zeros((1, 2)), np.zeros((1, 1)), _data(), max_iterations=1)
    largest = max(np.abs(fit.A).max(), np.abs(fit.B).max(), np.abs(fit.C).max())
    assert largest < 1e-3 * MAX_COEFFICIENT
    Model(path="fb", fs=FS, A=fit.A, B=fit.B, C=fit.C, D=fit.D)
