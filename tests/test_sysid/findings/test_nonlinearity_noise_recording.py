"""input-nonlinearity on the noise recording: the harmonic columns against its residual, a linear misfit left out.

The seed's FB plant: its noise recording peaks 13 dB above the sweeps, so a cubic at H3 -22 dB at the
session's largest input is -51 dB on the sweeps. A linear part fitted through it short of the true order
(here the true plant balanced-truncated to 4 of its 7 states, as identify ended on that session) leaves
the sweeps a misfit the harmonic columns explain a few per cent of; on the noise recording, whose
Gaussian input makes every linear misfit orthogonal to the columns' higher Hermite parts, they explain
the nonlinearity, and nothing of the misfit alone.
"""

import pytest
from conftest import short_spec

from sysid.core import lti
from sysid.core.model import Model
from sysid.findings import DiagnosisContext
from sysid.findings.nonlinearity import EXPLAINED, nonlinearity_finding
from sysid.simulate import simulate_session
from sysid.validation.compare import compare


def truncated_finding(effects: list[str], order: int = 4) -> dict:
    session = simulate_session(short_spec("fb", 0), effects=effects)
    true = Model.from_dict(session.truth.get("base_plant", session.truth["plant"]))
    A, B, C, D = lti.balanced_truncation(true.A, true.B, true.C, true.D, order=order)[:4]
    model = Model(path="fb", fs=true.fs, A=A, B=B, C=C, D=D, delay=true.delay)
    return nonlinearity_finding(DiagnosisContext(model, session.noise, session.sweeps, compare(model, session.sweeps)))


def test_a_nonlinearity_the_noise_recording_drives_is_found_there():
    found = truncated_finding(["input-nonlinearity:h2_db=-120,h3_db=-22"])
    assert found["evidence"]["explained_fraction"] < EXPLAINED  # the sweeps alone miss it (1 %)
    assert found["evidence"]["noise_explained_fraction"] >= 2 * EXPLAINED  # 25 %
    assert found["significant"]


@pytest.mark.parametrize("order", [3, 5])
def test_a_linear_misfit_alone_explains_nothing_on_the_noise_recording(order):
    # 7-10x the floor on the sweeps, and the columns explain under 1e-5 of the noise recording's residual.
    found = truncated_finding([], order)
    assert found["evidence"]["noise_explained_fraction"] < 1e-3
    assert not found["significant"]
