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
belong in the default run once a design takes seconds (``REPRESENTATIVE``). The pairs that miss a check today,
and why in physical terms, are in BENCHMARKS.md "The prediction on the recorded path" (random 1, 4, 6, 7, 9, 10).
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
REPRESENTATIVE = ["seed", "random 3", "random 11"]
OTHERS = [f"random {seed}" for seed in RANDOM_FB_SEEDS if f"random {seed}" not in REPRESENTATIVE]
NAMES = [pytest.param(name, marks=pytest.mark.slow) for name in REPRESENTATIVE + OTHERS]


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


@pytest.mark.parametrize("name", NAMES)
def test_stable_on_the_true_plants(name):
    controller, _ = case(name)
    poles = closed_loop_poles(controller, _pair(name).s)
    assert np.max(np.abs(poles), initial=0.0) < 1.0


@pytest.mark.parametrize("name", NAMES)
def test_both_reaches_the_causal_feedforward_bound(name):
    controller, judged = case(name)
    bound = _mean(controller.limits["causal_ff_db"])
    assert judged.mean("both") >= min(bound - BOTH_SHORTFALL_DB, ENOUGH_DB), \
        f"{name}: both {judged.mean('both'):.1f} dB against the causal bound {bound:.1f} dB"


@pytest.mark.parametrize("name", NAMES)
def test_feedback_reaches_the_robust_bound(name):
    controller, judged = case(name)
    bound = _mean(controller.limits["feedback_db"])
    assert judged.mean("fb") >= bound - FEEDBACK_SHORTFALL_DB, \
        f"{name}: feedback {judged.mean('fb'):.1f} dB against the robust bound {bound:.1f} dB"


@pytest.mark.parametrize("name", NAMES)
def test_achieved_as_predicted_in_every_band(name):
    controller, judged = case(name)
    for part, achieved in judged.per_band.items():
        predicted = np.array(controller.predicted_attenuation_db[part])
        worst = np.max(np.abs(achieved - predicted)[JUDGED])
        assert worst <= PREDICTION_DB, f"{name} {part}: {np.round((achieved - predicted)[JUDGED], 1)}"


@pytest.mark.parametrize("name", NAMES)
def test_no_band_louder_than_the_stated_limit(name):
    controller, judged = case(name)
    limit = controller.provenance["options"]["max_amplification_db"]
    for part, achieved in judged.per_band.items():
        assert np.min(achieved[JUDGED]) >= -limit, f"{name} {part}: {np.round(achieved[JUDGED], 1)}"


@pytest.mark.parametrize("name", NAMES)
def test_w_keeps_its_gain_bound_below_the_bands(name):
    # Below 20 Hz no band asks for anything, but a chin microphone's wind and handling noise is there. The bound is
    # held on the fit's log-spaced grid and the truncation may keep the fitted filter's gain on the dense grid:
    # GRID_DB between the two (random 13: 31.3 dB here; 62 dB at 2 Hz before the bound reached below 7.5 Hz).
    controller, _ = case(name)
    f = np.linspace(0.5, BANDS[0][1], 400)
    mean_square = float(np.mean(np.abs(controller.ff.frequency_response(f, controller.fs)) ** 2))
    bound = controller.provenance["options"]["max_ff_gain_db"]
    assert 10.0 * np.log10(mean_square) <= bound + GRID_DB, f"{name}: {10.0 * np.log10(mean_square):.1f} dB"
