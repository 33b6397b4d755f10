"""delay: the fixed-pole scan finds a missing delay exactly, and a long one leads the ranking."""

import pytest
from conftest import SHORT
from effect_sessions import WORKFLOW_OPTIONS, effect_case
from effect_units import true_context

from sysid import effects
from sysid.core.thresholds import LEADING_PHASE_DEG
from sysid.diagnose import diagnose, format_findings
from sysid.identify import identify
from sysid.random_plant import random_session
from sysid.findings.delay import delay_finding, scan_delay


@pytest.mark.parametrize("samples", [3, 23])
def test_the_scan_finds_the_missing_delay_of_the_true_plant(samples):
    ctx = true_context("ff", 5, (f"delay:{samples}",))
    best, costs = scan_delay(ctx)
    assert best == samples
    assert costs[0] > 2 * costs[best]


def test_a_long_missing_delay_leads_and_a_short_one_does_not():
    long = delay_finding(true_context("ff", 5, ("delay:23",)))
    assert long["significant"] and long["params"]["samples"] == 23 and long["evidence"]["leads"]
    assert long["evidence"]["excess_phase_deg"] == pytest.approx(360 * 4000 * 23 / 44100)
    short = delay_finding(true_context("ff", 5, ("delay:2",)))
    assert short["evidence"]["excess_phase_deg"] < LEADING_PHASE_DEG and not short["evidence"]["leads"]


def test_a_delay_the_model_bent_its_poles_for_is_confirmed_from_a_fresh_start():
    # Random FB helmet 31 behind 31 samples, fitted without them at its nominal 6 states (633x the floor): the
    # model's poles mimic the delay, so both scans are flat at them and its quick refit behind 31 samples gains
    # 1.13x; refits from the generic poles' fit behind 0 and 31 samples validate at 26x and 1.8x.
    session, model = effect_case("fb", 31, ("delay:31",))
    findings = diagnose(model, session.noise, session.sweeps)
    top = findings.significant[0]
    assert top["effect"] == "delay" and abs(top["params"]["samples"] - 31) <= 1, format_findings(findings)
    assert top["evidence"]["refit_gain"] > 5.0


def test_a_fresh_start_at_a_local_minimum_is_no_reference():
    # Clean random FB helmet 31 + 500, self-identified at 16 states and 1.42x the floor: the refit from the
    # generic poles' start lands 4.4x worse at the model's delay than a sample later; against the model's own
    # refit there, the sample later gains 1.01x, and no delay is named.
    session = random_session(531, "fb", **SHORT)
    model = identify(session.noise, session.sweeps, "fb", WORKFLOW_OPTIONS).model
    found = next(f for f in diagnose(model, session.noise, session.sweeps) if f["effect"] == "delay")
    assert not found["significant"] and found["evidence"]["refit_gain"] < 1.1, found["explanation"]


def test_no_delay_on_the_true_plant():
    found = delay_finding(true_context("ff", 5, ()))
    assert not found["significant"] and found["params"]["samples"] == 0


def test_the_registry_entry():
    delay = effects.get("delay")
    assert delay.detect is delay_finding and set(delay.needs) == {"resonance", "highpass", "lowpass"}
    assert delay.auto_params({"samples": 7, "total_samples": 9}) == {"samples": 7}
