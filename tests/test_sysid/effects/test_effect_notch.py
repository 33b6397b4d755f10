"""A user's own effect (the README's notch): registered by its module, then simulated, diagnosed and
refined to the noise floor like the built-in effects, and unregistered again."""

import importlib
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import short_spec
from effect_sessions import TEST_REFIT, effect_case
from repo import REPO

from sysid import effects
from sysid.diagnose import diagnose, format_findings
from sysid.refine import REFINE_EFFECTS, format_refinement, refine_auto
from sysid.simulate import SIMULATED_EFFECTS, simulate_session
from sysid.validation.compare import compare

README = REPO / "README.md"


@pytest.fixture
def notch():
    module = importlib.import_module("notch_effect")
    effects.register(module.NOTCH, replace=True)
    yield module
    effects.unregister("notch")


def notch_case(f0: float, q: float, seed: int = 5):
    # The model of the clean helmet, re-measured with the notch in series (as for the built-in factors).
    session = simulate_session(short_spec("ff", seed), effects=[f"notch:{f0},{q}"])
    return session, effect_case("ff", seed, ())[1]


def test_the_module_registers_itself_and_every_table_sees_it(notch):
    assert "notch" in effects.names() and "notch" in SIMULATED_EFFECTS and "notch" in REFINE_EFFECTS
    assert notch.detect in effects.detector_order()


def test_unregistered_it_is_gone_from_every_table(notch):
    effects.unregister("notch")
    assert "notch" not in SIMULATED_EFFECTS and "notch" not in REFINE_EFFECTS
    assert notch.detect not in effects.detector_order()


def test_the_notch_response_is_zero_at_f0_and_one_far_away(notch):
    b, a = notch.notch({"f0_hz": 1000.0, "q": 5.0}, 44100.0)
    z = np.exp(2j * np.pi * np.array([1000.0, 20.0, 10000.0]) / 44100.0)
    h = np.polyval(b[::-1], 1 / z) / np.polyval(a[::-1], 1 / z)
    assert abs(h[0]) < 1e-9 and abs(h[1]) == pytest.approx(1.0, abs=1e-3) and abs(h[2]) == pytest.approx(1.0, abs=0.01)


def test_a_notch_is_diagnosed_with_its_frequency_and_refined_to_the_floor(notch):
    session, model = notch_case(1200.0, 4.0)
    diagnosis = diagnose(model, session.noise, session.sweeps)
    significant = diagnosis.significant
    top_two = [f["effect"] for f in significant[:2]]
    assert "notch" in top_two, format_findings(diagnosis)
    found = next(f for f in significant if f["effect"] == "notch")
    assert found["params"]["f0_hz"] == pytest.approx(1200.0, rel=0.03), format_findings(diagnosis)
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    text = format_refinement(auto.steps, auto.stop_reason)
    assert "notch" in [s.effect for s in auto.steps if s.accepted], text
    assert compare(auto.model, session.sweeps).ratio <= 1.2, text


def test_a_session_without_the_notch_shows_none(notch):
    session, model = effect_case("ff", 3, ())
    diagnosis = diagnose(model, session.noise, session.sweeps)
    assert not any(f["effect"] == "notch" and f["significant"] for f in diagnosis), format_findings(diagnosis)


def test_the_readme_prints_this_module():
    # The README's worked example is this very module, so it runs as printed.
    text = README.read_text()
    block = re.search(r"```python\n(\"\"\"notch: .*?)```", text, re.S)
    assert block is not None, "README lacks the notch example"
    assert block.group(1) == (REPO / "tests" / "notch_effect.py").read_text()
