"""Tests of the feed-forward design (anc.feedforward): closed loop on the TRUE plants against the causal bound.

Each case is designed the way a user designs: on models identified from short sessions, for the road noise
recorded with ANC off (``control_cases.recording_with_anc_off``) at the board's latency; it is judged on
the true plants against a fresh realisation of the noise and against the causal bound computed on the
true plants (``anc.limits.feedforward_limits``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pytest

from anc.controller import Controller
from anc.disturbance import from_recording
from anc.feedforward import FeedforwardDesign, design_feedforward
from anc.limits import MAX_AMPLIFICATION_DB, Limits, feedforward_limits
from anc.prediction import band_centres
from anc.uncertainty import model_uncertainty

from control_cases import JUDGED, RANDOM_FB_SEEDS, identified, judge, random_pair, recording_with_anc_off, seed_pair

LATENCY = 2
# Where the causal bound is higher than this, this much is enough (dB).
ENOUGH_DB = 25.0
# Judged within this of the bound (mean 50 Hz-1 kHz) and of the prediction (every band 50 Hz-1 kHz), dB.
BOUND_SHORTFALL_DB = 2.0
PREDICTION_DB = 2.0
# The judge's spread per band between two realisations of the noise (4 s, third-octave bands), dB.
MEASUREMENT_DB = 0.5


@dataclass(frozen=True)
class Case:
    design: FeedforwardDesign
    bound: Limits
    judged: np.ndarray


@lru_cache(maxsize=None)
def case(name: str) -> Case:
    pair = seed_pair() if name == "seed" else random_pair(int(name.split()[1]))
    s_model, p_model = identified(name)
    # As ``anc.design`` designs: on the noise as the models see it (``Disturbance.modelled``).
    recording = recording_with_anc_off(pair.p)
    bound = feedforward_limits(pair.s, from_recording(recording, ff_model=pair.p).modelled(), LATENCY)
    disturbance = from_recording(recording, ff_model=p_model).modelled()
    design = design_feedforward(s_model, disturbance, LATENCY, model_uncertainty(s_model))
    predicted = [float(v) for v in design.attenuation_db]
    controller = Controller(s_model.fs, s_model, design.filter, None, LATENCY, band_centres(),
                            {"ff": predicted, "fb": [0.0] * len(predicted), "both": predicted})
    return Case(design, bound, judge(controller, pair).per_band["ff"])


# A design takes seconds (the seed pair: 5 CPU-s for a fit of 328 Kautz functions and its balanced truncation on
# one BLAS thread), the judge a few more: the seed pair in the default run, the random pairs marked slow.
DEFAULT = ["seed"]
SLOW = [f"random {seed}" for seed in RANDOM_FB_SEEDS]
NAMES = DEFAULT + [pytest.param(name, marks=pytest.mark.slow) for name in SLOW]


@pytest.mark.parametrize("name", NAMES)
def test_reaches_the_causal_bound_on_the_true_plants(name):
    c = case(name)
    bound = c.bound.mean("causal_ff")
    judged = float(np.mean(c.judged[JUDGED]))
    assert judged >= min(bound - BOUND_SHORTFALL_DB, ENOUGH_DB), \
        f"{name}: {judged:.1f} dB judged against the causal bound {bound:.1f} dB"


@pytest.mark.parametrize("name", NAMES)
def test_judged_as_predicted_in_every_band(name):
    c = case(name)
    difference = np.abs(c.judged - c.design.attenuation_db)[JUDGED]
    assert np.max(difference) <= PREDICTION_DB, f"{name}: {np.round(c.judged - c.design.attenuation_db, 1)}"


@pytest.mark.parametrize("name", NAMES)
def test_no_band_with_noise_is_louder_than_the_stated_limit(name):
    c = case(name)
    louder = -c.judged[c.design.audible]
    assert np.max(louder) <= MAX_AMPLIFICATION_DB + MEASUREMENT_DB, f"{name}: {np.round(c.judged, 1)}"


@pytest.mark.slow
def test_the_stored_filter_is_a_stable_reduction_of_the_fit():
    d = case("seed").design
    assert 0 < d.order <= d.full_order
    assert d.filter.A.shape == (d.order, d.order)
    assert np.max(np.abs(np.linalg.eigvals(d.filter.A))) < 1.0
    assert any("balanced truncation to order" in note for note in d.notes)


def test_a_capped_filter_keeps_the_cap_the_band_rule_and_says_what_it_costs():
    s_model, p_model = identified("seed")
    disturbance = from_recording(recording_with_anc_off(seed_pair().p), ff_model=p_model).modelled()
    full = case("seed").design
    cap = 40
    capped = design_feedforward(s_model, disturbance, LATENCY, model_uncertainty(s_model), max_order=cap)
    assert capped.order <= cap < full.order
    assert capped.filter.A.shape == (capped.order, capped.order)
    assert np.max(np.abs(np.linalg.eigvals(capped.filter.A))) < 1.0
    # The rule holds on the model at any order: no band beyond the stated limit.
    assert np.min(capped.attenuation_db[capped.audible]) >= -MAX_AMPLIFICATION_DB - 1e-9
    assert np.mean(capped.attenuation_db[JUDGED]) <= np.mean(full.attenuation_db[JUDGED]) + 0.1
    assert any("capped at 40 states" in note and "dB below the full order" in note for note in capped.notes)


def test_a_cap_below_one_state_is_refused():
    s_model, p_model = identified("seed")
    disturbance = from_recording(recording_with_anc_off(seed_pair().p), ff_model=p_model).modelled()
    with pytest.raises(ValueError, match="max_order"):
        design_feedforward(s_model, disturbance, LATENCY, max_order=0)


def test_the_notes_say_how_much_louder_w_makes_the_ear_above_the_bands():
    """Above 2 kHz only W's gain bound holds; where the recording's chin is at its floor (-60 dB of its peak) the
    seed pair's W makes the ear tens of dB louder there, which the note states. Checked here on a linear grid
    from the paths: |P + z^-L S W|^2 against |P|^2 for the floored chin spectrum, the incoherent ear beside it."""
    from anc.limits import CHIN_FLOOR
    from anc.wiener import relative_floor

    s_model, p_model = identified("seed")
    recording = recording_with_anc_off(seed_pair().p)
    disturbance = from_recording(recording, ff_model=p_model).modelled()
    design = case("seed").design
    notes = [n for n in design.notes if n.startswith("W makes the ear")]
    assert len(notes) == 1, design.notes
    louder, lo, hi = re.match(r"W makes the ear (\d+) dB louder at ([0-9.]+)-([0-9.]+) kHz", notes[0]).groups()
    f = np.linspace(1000.0 * float(lo), 1000.0 * float(hi), 4000)
    fs = s_model.fs
    spectra = disturbance.at(np.fft.rfftfreq(2 ** 16, 1.0 / fs))
    chin = np.interp(f, spectra.frequencies_hz, relative_floor(spectra.reference_psd, CHIN_FLOOR))
    uu = np.interp(f, spectra.frequencies_hz, spectra.incoherent_psd())
    P = p_model.frequency_response(f)
    G = s_model.frequency_response(f) * np.exp(-2j * np.pi * f * LATENCY / fs)
    GW = G * design.filter.frequency_response(f, fs)
    measured = 10.0 * np.log10(np.sum(uu + chin * np.abs(P + GW) ** 2) / np.sum(uu + chin * np.abs(P) ** 2))
    assert int(louder) > MAX_AMPLIFICATION_DB
    assert abs(measured - int(louder)) <= 1.5, (measured, notes[0])
