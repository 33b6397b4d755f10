"""diagnose: each hidden effect is the top significant finding with its parameters; clean data raise nothing."""

import json

import numpy as np
import pytest

from sysid.diagnose import Finding, diagnose, format_findings

from effect_sessions import effect_case, random_factor, reference_case

CONTRACT = {"effect", "significant", "score", "params", "explanation", "remedy", "evidence"}


def top(path, seed, *effects):
    session, model = effect_case(path, seed, tuple(effects))
    findings = diagnose(model, session.noise, session.sweeps)
    significant = findings.significant
    assert significant, format_findings(findings)
    return significant[0], findings, session


@pytest.mark.parametrize("path, seed", [("fb", 3), ("ff", 3), ("ff", 8)])
def test_clean_sessions_have_no_significant_finding(path, seed):
    session, model = effect_case(path, seed, ())
    findings = diagnose(model, session.noise, session.sweeps)
    assert findings.significant == [], format_findings(findings)
    assert all(set(f.to_dict()) == CONTRACT for f in findings)
    text = json.dumps(findings.to_dicts(), allow_nan=False)
    # The typed records survive the JSON round trip.
    assert [Finding.from_dict(d) for d in json.loads(text)] == list(findings)


@pytest.mark.parametrize("path, samples", [("ff", 23), ("fb", 14), ("ff", 6)])
def test_delay_is_found_with_its_length(path, samples):
    finding, _, _ = top(path, 5, f"delay:{samples}")
    assert finding["effect"] == "delay"
    # The scan sees the response onset, which the plant's own first samples blur by one sample.
    assert abs(finding["params"]["samples"] - samples) <= 1
    assert "cm of sound path" in finding["explanation"]
    assert finding["remedy"].startswith("refine --add delay:")


def test_periodic_disturbance_lines_are_found():
    finding, _, _ = top("ff", 5, "periodic-disturbance:50,3,1e-3")
    assert finding["effect"] == "periodic-disturbance"
    assert finding["params"]["frequencies_hz"] == pytest.approx([50.0, 100.0, 150.0], abs=0.05)
    assert finding["params"]["levels_fs"][0] == pytest.approx(1e-3, rel=0.1)
    assert "mains hum" in finding["explanation"]


def test_input_nonlinearity_harmonics_are_estimated():
    finding, _, _ = top("ff", 5, "input-nonlinearity:-40,-35")
    assert finding["effect"] == "input-nonlinearity"
    assert finding["params"]["h2_db"] == pytest.approx(-40.0, abs=1.5)
    assert finding["params"]["h3_db"] == pytest.approx(-35.0, abs=1.5)


@pytest.mark.parametrize("path", ["ff", "fb"])
def test_input_noise_snr_is_estimated(path):
    finding, _, _ = top(path, 5, "input-noise:8")
    assert finding["effect"] == "input-noise"
    assert finding["params"]["input_snr_db"] == pytest.approx(8.0, abs=1.0)


# Stated tolerances of the series-factor estimates (the sweeps' SNR makes them much tighter in practice).
FACTOR_TOLERANCE = {"f0_hz": 0.03, "q": 0.2, "corner_hz": 0.1}
GAIN_TOLERANCE_DB = 1.0


def check_factor(kind, path, seed):
    spec, truth = random_factor(kind, np.random.default_rng(seed))
    session, model = reference_case(path, seed, (spec,))
    findings = diagnose(model, session.noise, session.sweeps)
    assert findings.significant, format_findings(findings)
    top = findings.significant[0]
    assert top["effect"] == kind, (spec, format_findings(findings))
    assert [f["effect"] for f in findings.significant] == [kind], format_findings(findings)
    for name, value in truth.items():
        if name in FACTOR_TOLERANCE:
            assert top["params"][name] == pytest.approx(value, rel=FACTOR_TOLERANCE[name]), (spec, name)
        elif name == "gain_db":
            assert top["params"][name] == pytest.approx(value, abs=GAIN_TOLERANCE_DB), spec
        else:
            assert top["params"][name] == value, (spec, name)
    assert top["remedy"].startswith(f"refine --add {kind}:")
    return top


@pytest.mark.parametrize("kind, path, seed", [("resonance", "ff", 41), ("resonance", "fb", 42), ("highpass", "fb", 43),
                                              ("highpass", "ff", 44), ("lowpass", "ff", 45), ("lowpass", "fb", 46)])
def test_series_factors_are_found_with_their_parameters(kind, path, seed):
    top = check_factor(kind, path, seed)
    words = {"resonance": "a mode the model lacks", "highpass": "phase lead", "lowpass": "phase lag"}
    assert words[kind] in top["explanation"]


def test_a_factor_taken_in_by_the_fit_leaves_the_model_under_modelled():
    # Identified on the session itself, the nominal-order model takes the 800 Hz mode in and gives
    # up the plant's weak 4.3 kHz mode: no factor fits what is left, more order does.
    session, model = effect_case("ff", 3, ("resonance:800,5,8",))
    findings = diagnose(model, session.noise, session.sweeps)
    top = findings.significant[0]
    assert [f["effect"] for f in findings.significant] == ["under-modelled"], format_findings(findings)
    assert top["params"]["suggested_order"] == model.order + 2
    assert top["remedy"] == "refine --add under-modelled"


@pytest.mark.parametrize("path", ["ff", "fb"])
def test_a_delay_is_not_mistaken_for_a_low_pass(path):
    session, model = reference_case(path, 7, ("delay:4",))
    findings = diagnose(model, session.noise, session.sweeps)
    assert [f["effect"] for f in findings.significant] == ["delay"], format_findings(findings)


def test_dc_offset_is_reported_from_the_recordings():
    finding, _, _ = top("fb", 5, "dc-offset:0.01")
    assert finding["effect"] == "dc-offset"
    assert finding["params"]["offset_fs"] == pytest.approx(0.01, abs=1e-3)


def test_clipping_is_reported_with_its_fraction():
    finding, _, session = top("ff", 5, "clipping:1.3")
    assert finding["effect"] == "clipping"
    assert finding["params"]["fraction"] == pytest.approx(max(s.clipped_fraction[1] for s in session.sweeps), rel=1e-6)


def test_clock_drift_is_found_with_its_rate():
    finding, _, _ = top("ff", 5, "clock-drift:50")
    assert finding["effect"] == "clock-drift"
    assert finding["params"]["ppm"] == pytest.approx(50.0, rel=0.1)
    assert "clock" in finding["explanation"]


def test_time_variation_is_found():
    finding, _, _ = top("ff", 5, "time-variation:5")
    assert finding["effect"] == "time-variation"
    assert "changed while recording" in finding["explanation"]


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(20, 26))
@pytest.mark.parametrize("path", ["fb", "ff"])
def test_clean_sessions_many_seeds(path, seed):
    session, model = effect_case(path, seed, ())
    assert diagnose(model, session.noise, session.sweeps).significant == []


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(20, 24))
def test_delay_many_seeds(seed):
    samples = int(np.random.default_rng(seed).integers(5, 50))
    finding, _, _ = top("ff", seed, f"delay:{samples}")
    assert finding["effect"] == "delay" and abs(finding["params"]["samples"] - samples) <= 1


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(50, 54))
@pytest.mark.parametrize("path", ["fb", "ff"])
@pytest.mark.parametrize("kind", ["resonance", "highpass", "lowpass"])
def test_series_factors_many_seeds(kind, path, seed):
    check_factor(kind, path, seed)


SLOW_CASES = [("delay", lambda rng: f"delay:{int(rng.integers(8, 50))}"),
              ("periodic-disturbance", lambda rng: f"periodic-disturbance:{rng.choice([50.0, 60.0, 41.7])},3,1e-3"),
              ("clock-drift", lambda rng: f"clock-drift:{rng.uniform(20, 100) * rng.choice([-1, 1]):.1f}"),
              ("input-noise", lambda rng: f"input-noise:{rng.uniform(3, 12):.1f}"),
              ("time-variation", lambda rng: f"time-variation:{rng.uniform(4, 8):.1f}")]


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(30, 33))
@pytest.mark.parametrize("path", ["fb", "ff"])
@pytest.mark.parametrize("kind, make", SLOW_CASES, ids=[c[0] for c in SLOW_CASES])
def test_random_effects_are_the_top_finding(kind, make, path, seed):
    spec = make(np.random.default_rng(seed))
    finding, _, _ = top(path, seed, spec)
    assert finding["effect"] == kind, spec
