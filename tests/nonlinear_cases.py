"""Nonlinear-driver sessions and the workflow check shared by the Hammerstein and Wiener-Hammerstein driver tests.

``polynomial_session``: a random helmet's short session whose drive passes u + a2 u^2 with the second harmonic at
``level_db`` at the sweeps' amplitude (simulate states a polynomial's levels at the session's largest input, where
H2 is larger); ``refined_to_the_floor``: identified on the session, input-nonlinearity named among the top two
findings, ``refine --auto`` within 1.5x of the noise floor with the core within two states of the true order.
"""

import numpy as np
from conftest import SHORT

from sysid.core.model import Model
from sysid.diagnose import diagnose
from sysid.identify import identify
from sysid.random_plant import random_session
from sysid.refine import format_refinement, refine_auto
from sysid.refits.machinery import REFIT_OPTIONS

__all__ = ["polynomial_session", "refined_to_the_floor"]


def polynomial_session(seed: int, path: str, level_db: float, extra: str = ""):
    """The session of u + a2 u^2 (H2 ``level_db`` at the sweeps' amplitude); ``extra``: more effect parameters."""
    probe = random_session(seed, path, **SHORT)
    ratio = max(np.max(np.abs(r.u)) for r in (probe.noise, *probe.sweeps)) / np.max(np.abs(probe.sweeps[0].u))
    return random_session(seed, path, effects=[f"input-nonlinearity:h2_db={level_db + 20 * np.log10(ratio):.3f},"
                                               f"h3_db=-120{extra}"], **SHORT)


def refined_to_the_floor(session, path: str):
    """(refinement, its text, true plant) of the session's self-identified workflow, asserting issue 28's check."""
    true = Model.from_dict(session.truth["plant"])
    model = identify(session.noise, session.sweeps, path, REFIT_OPTIONS).model
    findings = diagnose(model, session.noise, session.sweeps)
    named = [f["effect"] for f in findings.significant[:2]]
    assert "input-nonlinearity" in named, named
    auto = refine_auto(model, session.noise, session.sweeps, REFIT_OPTIONS)
    text = format_refinement(auto.steps, auto.stop_reason)
    assert auto.after.ratio <= 1.5, text
    assert abs(auto.model.order - true.order) <= 2, (true.order, text)
    return auto, text, true
