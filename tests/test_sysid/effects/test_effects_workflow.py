"""Every effect in the user's own workflow: random helmet, identify on the session, diagnose, refine --auto.

One generic test runs on every effect of ``SIMULATED_EFFECTS`` at random parameters
(``sysid.simulate.random_effect``), both paths, alone and in pairs and triples: the
effect is among the top two significant findings, its estimated parameter within the
stated tolerance, and ``refine --auto`` ends at most ``AT_FLOOR`` times the noise floor
or names what it cannot model. Clean random helmets raise at most 2 % false alarms (where
identification ends above twice the floor, under-modelled is the required answer, not one). The
default run takes a representative handful on the appendix-A plants; the random helmets
are slow-marked.
"""

import numpy as np
import pytest
from conftest import SHORT, short_spec
from effect_sessions import TEST_REFIT, WORKFLOW_OPTIONS

from sysid.core.thresholds import AT_FLOOR, UNDER_MODELLED_EXCESS
from sysid.diagnose import diagnose, format_findings
from sysid.identify import IdentificationOptions, identify
from sysid.random_plant import random_session
from sysid.refine import format_refinement, refine_auto
from sysid.simulate import SIMULATED_EFFECTS, random_effect, simulate_session

OPTIONS = WORKFLOW_OPTIONS
# Stated tolerance of each checked parameter: absolute in its units, or relative (suffix %).
TOLERANCE = {"samples": 1, "frequencies_hz": 0.1, "h2_db": 1.5, "input_snr_db": 1.0, "ppm": "10%",
             "ear_offset_fs": "10%", "f0_hz": "3%", "corner_hz": "10%"}
# What refine --auto cannot bring to the floor, and the stop reason that must name it instead: a plant
# that changes, and noise on the measured input, which passes through the path into every prediction
# (the true path itself validates at the bound it sets: 12.7x-162x the floor at 6-10 dB input SNR).
UNMODELLABLE = {"time-variation", "input-noise"}
SERIES_FACTORS = ("resonance", "highpass", "lowpass")
# identify estimates the latency before the core fit (the response onset less one sample, and the
# plant's first samples blur the onset by up to a few samples more), so a delay is held by the model.
LATENCY_SHORT_BY_AT_MOST = 4


def rolloff_lag(session) -> int:
    """Samples a delay line may read past the pure delay by holding the plant's own roll-offs.

    A first-order low-pass of corner fc lags like fs / (2 pi fc) samples of pure delay below fc
    (its group delay at DC), and its response starts as t, or t^2 behind two: its first samples are
    too small for the data to tell from delay (random helmet 100 FF, roll-offs at 3.0 and 5.2 kHz,
    3.7 samples: refitted output-error costs within 0.23 % of each other over total delays 31-38, the
    true one 34). Whole samples, rounded up; 0 for a plant without roll-offs."""
    generator = session.truth.get("generator", {})
    lag = sum(generator["fs"] / (2 * np.pi * fc) for fc in generator.get("rolloff_hz", ()))
    return int(np.ceil(lag))


def within(name, value, truth) -> bool:
    value = value[0] if isinstance(value, list) else value
    tolerance = TOLERANCE[name]
    if isinstance(tolerance, str):
        return abs(value / truth - 1) <= float(tolerance.rstrip("%")) / 100
    return abs(value - truth) <= tolerance


def check_workflow(session, path, kinds, drawn):
    model = identify(session.noise, session.sweeps, path, OPTIONS).model
    findings = diagnose(model, session.noise, session.sweeps)
    text = f"{[d[0] for d in drawn]}\n{format_findings(findings)}"
    top_two = findings.significant[:2]
    for kind, (_, name, truth) in zip(kinds, drawn):
        hit = next((f for f in top_two if f["effect"] == kind), None)
        if kind == "delay":
            # The hidden delay adds to the plant's own (a random helmet has 0-64 samples of its own).
            total = truth + session.truth["base_plant"].get("delay", 0)
            longest = total + rolloff_lag(session)
            assert total - LATENCY_SHORT_BY_AT_MOST <= model.delay <= longest, (total, longest, model.delay, text)
            # Held by the model, the delay is nothing missing (no finding to ask for); with other effects
            # the model is above the floor for them, and refine --auto below judges the end.
            continue
        if kind in SERIES_FACTORS:
            # Identified on its own session a series factor is part of the path: the model holds it
            # (at the floor, nothing is missing) or has traded a weak mode for it (under-modelled).
            if findings.comparison.ratio > AT_FLOOR and len(kinds) == 1:
                assert hit is not None or top_two and top_two[0]["effect"] == "under-modelled", text
            continue
        if len(kinds) == 1:
            assert hit is not None, text
        if hit is not None and name is not None:
            assert within(name, hit["params"][name], truth), (name, truth, text)
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    text += "\n" + format_refinement(auto.steps, auto.stop_reason)
    if UNMODELLABLE & set(kinds):
        assert auto.after.ratio <= AT_FLOOR or "cannot be modelled" in auto.stop_reason, text
    else:
        assert auto.after.ratio <= AT_FLOOR, text


# The default run: a representative handful on the appendix-A plants, self-identified. On the clipped
# FB session identify alone stops at order 3 (the seed plant has 7), and on the drifting-clock session
# at a delay the drift smeared: the corrections' refits identify anew on the corrected data.
HANDFUL = [("ff", 21, ("delay",)), ("fb", 22, ("clipping",)), ("ff", 23, ("dc-offset",)),
           ("ff", 24, ("input-nonlinearity",)), ("ff", 25, ("clock-drift", "periodic-disturbance"))]


@pytest.mark.parametrize("path, seed, kinds", HANDFUL,
                         ids=["+".join(h[2]) for h in HANDFUL])
def test_effect_in_the_self_identified_workflow(path, seed, kinds):
    rng = np.random.default_rng(seed)
    drawn = [random_effect(kind, rng) for kind in kinds]
    # clock drift of the wrong sign would need the slow clock's tail; both signs run in the slow set.
    session = simulate_session(short_spec(path, seed), effects=[d[0] for d in drawn])
    check_workflow(session, path, kinds, drawn)


EFFECTS = sorted(SIMULATED_EFFECTS)
PAIRS = [("delay", "periodic-disturbance"), ("dc-offset", "lowpass"), ("clock-drift", "input-nonlinearity")]
TRIPLES = [("delay", "clipping", "periodic-disturbance"), ("clock-drift", "dc-offset", "resonance")]


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("path", ["fb", "ff"])
@pytest.mark.parametrize("kinds", [(k,) for k in EFFECTS] + PAIRS + TRIPLES, ids=lambda k: "+".join(k))
def test_every_effect_on_random_helmets(kinds, path, seed):
    rng = np.random.default_rng([seed, len(kinds), ord(path[1])])
    drawn = [random_effect(kind, rng) for kind in kinds]
    session = random_session(100 + seed, path, effects=[d[0] for d in drawn], **SHORT)
    check_workflow(session, path, kinds, drawn)


def clean_verdict(seed: int, path: str) -> tuple[float, list[str]]:
    """(rms / floor of the model identified on a clean short random-helmet session, its significant findings)."""
    session = random_session(seed, path, **SHORT)
    model = identify(session.noise, session.sweeps, path, OPTIONS).model
    findings = diagnose(model, session.noise, session.sweeps)
    return findings.comparison.ratio, [f["effect"] for f in findings.significant]


@pytest.mark.slow
def test_clean_random_helmets_raise_at_most_two_percent_false_alarms():
    # 100 clean sessions, self-identified. Where identification ends above UNDER_MODELLED_EXCESS times
    # the floor, under-modelled is the required answer (not a false alarm; identify's shortfall) and
    # must be there; any other significant finding on a clean session is a false alarm.
    alarms, short = [], []
    for seed in range(50):
        for path in ("fb", "ff"):
            ratio, significant = clean_verdict(500 + seed, path)
            if ratio > UNDER_MODELLED_EXCESS:
                assert "under-modelled" in significant, (seed, path, ratio, significant)
                short.append((seed, path, ratio))
            false = [e for e in significant if not (e == "under-modelled" and ratio > UNDER_MODELLED_EXCESS)]
            if false:
                alarms.append((seed, path, ratio, false))
    assert len(alarms) <= 2, (alarms, short)
