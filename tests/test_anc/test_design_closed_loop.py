"""The whole design (``anc.design``) on identified models, the noise given as a recording, judged on the TRUE plants.

Issue 26's checks, per pair of ``control_cases``: stable on the true FB path; "both" within 3 dB of the
causal feed-forward bound of the identified models (or >= 25 dB where the bound is higher); feedback at
least the robust bound - 1.5 dB; achieved within 2 dB of predicted in every band 50 Hz-1 kHz; no band
louder than the stated amplification limit. The bounds are the ones the controller records
(``Controller.limits``), so the check is against the limit the paths allow, never against the same
design made on the true plants.

A design takes 14-47 CPU-s (BENCHMARKS.md "Frequency responses by the Schur form"), minutes of wall time on a
shared 2-core machine with the judge's closed loops,
so every pair is marked slow; the seed pair and random pairs 3 and 11 are the representative handful that
belong in the default run once a design takes seconds (``REPRESENTATIVE``). The checks a pair misses today are
expected to fail (``MISSES``, non-strict: a design that mends one shows as XPASS), with why in physical terms in
BENCHMARKS.md "A band's power over linear frequency"; the issue asks for the seed pair and at least
``RANDOM_PASSING`` random pairs to pass every check (``test_enough_random_pairs_pass_every_check``).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from control_cases import JUDGED, RANDOM_FB_SEEDS, identified, judge, random_pair, recording_with_anc_off, seed_pair

from anc import design
from anc.closed_loop import closed_loop_poles
from anc.disturbance import from_recording
from anc.prediction import BANDS

BOTH_SHORTFALL_DB = 3.0
ENOUGH_DB = 25.0
FEEDBACK_SHORTFALL_DB = 1.5
PREDICTION_DB = 2.0
# W's gain bound below the bands, as measured on a dense linear grid against the fit's own (dB).
GRID_DB = 2.0
RANDOM_PASSING = 8
REPRESENTATIVE = ["seed", "random 3", "random 11"]
OTHERS = [f"random {seed}" for seed in RANDOM_FB_SEEDS if f"random {seed}" not in REPRESENTATIVE]
# The checks missed today (pair, check), and what limits them (BENCHMARKS.md "A band's power over linear frequency").
BOTH, PREDICTED = "both_at_causal_bound", "as_predicted_every_band"
MISSES = {
    ("random 1", BOTH): "the design's rules: the bound within them is 17.9 dB against 25 needed",
    ("random 4", BOTH): "the design's rules: the bound within them with Q in the loop is 18.4 dB against 19.3 needed",
    ("random 9", BOTH): "the design's rules: the bound within them is 5.7 dB against 12.4 needed",
    ("random 10", BOTH): "the design's rules: the bound within them is 2.3 dB against 6.6 needed",
    ("random 6", PREDICTED): "the 500 Hz band 2.2 dB deeper than predicted: S's model error (0.1 dB with the true S)",
    ("random 9", PREDICTED): "the 50 Hz band, cancelled 25 dB deep, reads 4.1 dB shallower through the judge's 0.5 s "
                             "Welch segments (0.4-1.1 dB with 1-7.75 s segments)",
}


def _pair(name: str):
    return seed_pair() if name == "seed" else random_pair(int(name.split()[1]))


@lru_cache(maxsize=None)
def case(name: str):
    """(controller, judgement) of the pair ``name``: designed on its identified models with its recording."""
    pair = _pair(name)
    s_model, p_model = identified(name)
    disturbance = from_recording(recording_with_anc_off(pair.p), s_model.fs, ff_model=p_model)
    controller = design(s_model, p_model, disturbance)
    return controller, judge(controller, pair)


def _mean(values) -> float:
    chosen = [v for v, j in zip(values, JUDGED) if j and v is not None]
    return float(np.mean(chosen))


def _unstable(name: str) -> str | None:
    controller, _ = case(name)
    largest = float(np.max(np.abs(closed_loop_poles(controller, _pair(name).s)), initial=0.0))
    return None if largest < 1.0 else f"{name}: closed-loop pole of radius {largest:.4f} on the true plants"


def _both_short(name: str) -> str | None:
    controller, judged = case(name)
    bound = _mean(controller.limits["causal_ff_db"])
    if judged.mean("both") >= min(bound - BOTH_SHORTFALL_DB, ENOUGH_DB):
        return None
    return f"{name}: both {judged.mean('both'):.1f} dB against the causal bound {bound:.1f} dB"


def _feedback_short(name: str) -> str | None:
    controller, judged = case(name)
    bound = _mean(controller.limits["feedback_db"])
    if judged.mean("fb") >= bound - FEEDBACK_SHORTFALL_DB:
        return None
    return f"{name}: feedback {judged.mean('fb'):.1f} dB against the robust bound {bound:.1f} dB"


def _mispredicted(name: str) -> str | None:
    controller, judged = case(name)
    for part, achieved in judged.per_band.items():
        error = achieved - np.array(controller.predicted_attenuation_db[part])
        if np.max(np.abs(error)[JUDGED]) > PREDICTION_DB:
            return f"{name} {part}: achieved - predicted {np.round(error[JUDGED], 1)}"
    return None


def _louder_than_stated(name: str) -> str | None:
    controller, judged = case(name)
    limit = controller.provenance["options"]["max_amplification_db"]
    for part, achieved in judged.per_band.items():
        if np.min(achieved[JUDGED]) < -limit:
            return f"{name} {part}: {np.round(achieved[JUDGED], 1)}"
    return None


def _w_gain_above_bound(name: str) -> str | None:
    # Below 20 Hz no band asks for anything, but a chin microphone's wind and handling noise is there. The bound is
    # held on the fit's log-spaced grid and the truncation may keep the fitted filter's gain on the dense grid:
    # GRID_DB between the two (random 13: 31.3 dB here; 62 dB at 2 Hz before the bound reached below 7.5 Hz).
    controller, _ = case(name)
    f = np.linspace(0.5, BANDS[0][1], 400)
    gain_db = 10.0 * np.log10(float(np.mean(np.abs(controller.ff.frequency_response(f, controller.fs)) ** 2)))
    bound = controller.provenance["options"]["max_ff_gain_db"]
    return None if gain_db <= bound + GRID_DB else f"{name}: W's mean-square gain below 20 Hz {gain_db:.1f} dB"


CHECKS = {"stable_on_true_plants": _unstable, BOTH: _both_short, "feedback_at_robust_bound": _feedback_short,
          PREDICTED: _mispredicted, "no_band_louder_than_limit": _louder_than_stated,
          "w_gain_bound_below_bands": _w_gain_above_bound}


def _cases() -> list:
    """(check, pair) for every check and pair, slow; the checks a pair misses today expected to fail (``MISSES``)."""
    return [pytest.param(check, name, id=f"{check}-{name}", marks=[pytest.mark.slow] + (
                [pytest.mark.xfail(reason=MISSES[name, check], strict=False)] if (name, check) in MISSES else []))
            for check in CHECKS for name in REPRESENTATIVE + OTHERS]


@pytest.mark.parametrize("check, name", _cases())
def test_pair_passes_check(check, name):
    assert (failure := CHECKS[check](name)) is None, failure


@pytest.mark.slow
def test_enough_random_pairs_pass_every_check():
    failures = {name: [f for check in CHECKS.values() if (f := check(name)) is not None]
                for name in ["seed"] + [f"random {seed}" for seed in RANDOM_FB_SEEDS]}
    assert not failures["seed"], failures["seed"]
    passing = [name for name, found in failures.items() if name != "seed" and not found]
    assert len(passing) >= RANDOM_PASSING, f"{len(passing)} random pairs pass every check ({', '.join(passing)}): " \
        + "; ".join(f for found in failures.values() for f in found)
