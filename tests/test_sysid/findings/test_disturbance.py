"""periodic-disturbance finding: a mode rung by the drive's distortion is no hum; a hum beside it still is.

Random helmet 13's FF path has a lightly damped mode (Q about 30) at 91 Hz. Behind a driver u + a2 u^2
(second harmonic -15 dB at the sweeps' amplitude), u^2 of the noise recording rings it: the residual of
the linear plant peaks there like a line the input neither holds nor explains, present in both sweeps'
residuals while their second harmonic passes 45 Hz, but its phase wanders at the mode's bandwidth
(``sysid.io.line_stationarity``). It was named a periodic disturbance, and refinement fitted a sinusoid
to it before the input map (2.56x the floor in the end, with a degree-7 polynomial).
"""

import numpy as np
import pytest
from conftest import SHORT
from nonlinear_cases import polynomial_session, refined_to_the_floor

from sysid.core.model import Model
from sysid.findings import DiagnosisContext
from sysid.findings.disturbance import disturbance_finding
from sysid.random_plant import random_session
from sysid.validation.compare import compare

DISTORTED = (13, "ff", -15.0)


def _linear_context(session) -> DiagnosisContext:
    """The context of the session's true plant without its input map: what the distortion leaves is the residual."""
    model = Model.from_dict(session.truth["base_plant"])
    return DiagnosisContext(model, session.noise, session.sweeps, compare(model, session.sweeps))


def test_a_mode_rung_by_the_drives_distortion_is_no_hum():
    ctx = _linear_context(polynomial_session(*DISTORTED))
    lines = ctx.value("session-lines").found[0]
    assert any(abs(f - 91.0) < 91.0 / 30.0 for f, _, _ in lines), lines  # the line search sees it
    found = disturbance_finding(ctx)
    assert not found["significant"], found["explanation"]
    assert found["evidence"]["not_stationary"] >= 1 and found["evidence"]["candidates"] == 0


@pytest.mark.parametrize("level", ["1e-4", "3e-4"])
def test_a_hum_beside_the_distortion_is_still_found(level):
    # The same session with mains hum at 1e-4 and 3e-4 FS (-80 and -70 dB; the drive's harmonics at -15 dB make
    # the sweeps' residual 100 times the hum): the hum is named in both sweeps (their quiet stretches show it),
    # the ringing mode is not.
    probe = random_session(13, "ff", **SHORT)
    ratio = max(np.max(np.abs(r.u)) for r in (probe.noise, *probe.sweeps)) / np.max(np.abs(probe.sweeps[0].u))
    session = random_session(13, "ff", effects=[f"input-nonlinearity:h2_db={-15.0 + 20 * np.log10(ratio):.3f},h3_db=-120",
                                                f"periodic-disturbance:50,3,{level}"], **SHORT)
    found = disturbance_finding(_linear_context(session))
    assert found["significant"], found["explanation"]
    frequencies = found["params"]["frequencies_hz"]
    assert min(frequencies) == pytest.approx(50.0, abs=0.2)
    assert all(abs(f / 50.0 - round(f / 50.0)) < 0.01 for f in frequencies), frequencies


@pytest.mark.slow
def test_the_distorted_session_is_refined_through_its_input_map_not_a_hum():
    # Identified on the session, diagnosed, ``refine --auto``: input-nonlinearity named and refined to the
    # floor at the true order +- 2, no sinusoid fitted to the mode, the map's degree that of the driver +- 2.
    auto, text, _ = refined_to_the_floor(polynomial_session(*DISTORTED), "ff")
    assert not any(step.effect == "periodic-disturbance" and step.accepted for step in auto.steps), text
    assert auto.model.input_nonlinearity is None or len(auto.model.input_nonlinearity) <= 2 + 2, text
