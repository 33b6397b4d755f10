"""refine: the added structure brings the validation error to the noise floor and survives JSON."""

import json
from pathlib import Path

import numpy as np
import pytest
from effect_sessions import TEST_REFIT, effect_case, random_factor, reference_case

from helmet_anc.cli import main
from sysid.core.errors import HelmetAncError
from sysid.core.model import Model
from sysid.refine import RefinementStep, format_refinement, refine, refine_auto
from sysid.simulate import write_session
from sysid.validation.compare import compare

BAND = np.linspace(20.0, 1500.0, 300)


def refined(path, seed, effect, add):
    session, model = effect_case(path, seed, (effect,))
    result = refine(model, session.noise, session.sweeps, add, TEST_REFIT)
    return session, model, result


def test_delay_refinement_reaches_the_noise_floor_and_survives_json(tmp_path):
    session, model, result = refined("ff", 5, "delay:23", "delay")
    assert result.before.ratio > 10
    assert result.model.delay in (23, 24)
    assert result.after.ratio <= 1.2
    assert result.model.history[-1]["effect"] == "delay"
    assert result.model.history[-1]["rms_after"] == pytest.approx(result.after.rms)
    # The re-identified core brings its own band; the nominal model's belonged to another fit.
    assert result.model.uncertainty is not None and result.model.uncertainty != model.uncertainty
    result.model.save(tmp_path / "m.json")
    again = Model.load(tmp_path / "m.json")
    assert again.uncertainty == result.model.uncertainty
    assert compare(again, session.sweeps).rms == pytest.approx(result.after.rms, rel=1e-9)


def test_periodic_disturbance_refinement():
    session, _, result = refined("ff", 5, "periodic-disturbance:50,3,1e-3", "periodic-disturbance")
    assert result.model.disturbance_frequencies == pytest.approx([50.0, 100.0, 150.0], abs=0.05)
    assert result.after.ratio <= 1.2


def test_input_nonlinearity_refinement():
    session, _, result = refined("ff", 5, "input-nonlinearity:-40,-35", "input-nonlinearity")
    assert result.model.input_nonlinearity is not None
    assert result.after.ratio <= 1.2


@pytest.mark.parametrize("effect, add", [
    ("highpass:60", "highpass:corner_hz=60"),
    ("lowpass:1500,1", "lowpass:corner_hz=1500,order=1"),
    ("resonance:3400,8,10", "resonance:f0_hz=3400,q=8"),
])
def test_given_structures_reach_the_noise_floor(effect, add, tmp_path):
    # A series factor is added to a model of the same helmet without it (see effect_sessions).
    session, model = reference_case("ff", 5, (effect,))
    result = refine(model, session.noise, session.sweeps, add, TEST_REFIT)
    assert result.before.ratio > 5
    assert result.after.ratio <= 1.2
    result.model.save(tmp_path / "m.json")
    assert compare(Model.load(tmp_path / "m.json"), session.sweeps).rms == pytest.approx(result.after.rms, rel=1e-9)


def test_input_noise_refinement_removes_the_gain_bias():
    session, model, result = refined("ff", 5, "input-noise:8", "input-noise")

    def bias_db(m):
        return np.max(np.abs(20 * np.log10(np.abs(m.frequency_response(BAND) / session.plant.frequency_response(BAND)))))

    assert bias_db(model) > 0.4
    assert bias_db(result.model) < 0.3
    assert result.model.identification["estimator"].startswith("bias-compensated")


@pytest.mark.slow
def test_auto_names_the_bound_the_input_noise_sets():
    # Errors in variables: the input's own noise through the path is in every prediction, so the true
    # path itself validates far above the floor; refine --auto ends near that bound and says so.
    session, model = effect_case("ff", 5, ("input-noise:5",))
    truth = compare(session.plant, session.sweeps).ratio
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    text = format_refinement(auto.steps, auto.stop_reason)
    assert truth > 3.0
    assert "cannot be modelled: input-noise (input SNR" in auto.stop_reason, text
    assert auto.after.ratio <= 1.2 * truth, text


def test_auto_finds_and_fixes_delay_and_hum_together():
    session, model = effect_case("ff", 6, ("delay:23", "periodic-disturbance:50,2,1e-3"))
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    final, steps = auto.model, auto.steps
    kept = [s for s in steps if s.accepted]
    assert "periodic-disturbance" in {s.effect for s in kept} and {s.effect for s in kept} <= {"delay",
                                                                                                "periodic-disturbance"}
    # The delay is its own step, or the re-identification behind the disturbance model found it (and says so).
    assert any(s.effect == "delay" or "total_delay_samples" in s.params for s in kept)
    assert final.delay in (22, 23, 24)
    assert compare(final, session.sweeps).ratio <= 1.2
    assert [h["effect"] for h in final.history] == [s.effect for s in steps if s.accepted]
    assert auto.stop_reason == "at the floor"
    assert "stopped: at the floor" in format_refinement(steps, auto.stop_reason)


def auto_fixes_factor(kind, path, seed):
    spec, _ = random_factor(kind, np.random.default_rng(seed))
    session, model = reference_case(path, seed, (spec,))
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    final, steps = auto.model, auto.steps
    assert [s.effect for s in steps if s.accepted] == [kind], (spec, format_refinement(steps))
    assert compare(final, session.sweeps).ratio <= 1.2, (spec, format_refinement(steps))
    assert final.stable and final.history[-1]["effect"] == kind
    return final


@pytest.mark.parametrize("kind, path, seed", [("resonance", "fb", 41), ("highpass", "fb", 43), ("lowpass", "ff", 45)])
def test_auto_adds_the_missing_series_factor(kind, path, seed, tmp_path):
    final = auto_fixes_factor(kind, path, seed)
    final.save(tmp_path / "m.json")
    assert Model.load(tmp_path / "m.json").history[-1]["params"] == final.history[-1]["params"]


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(50, 53))
@pytest.mark.parametrize("path", ["fb", "ff"])
@pytest.mark.parametrize("kind", ["resonance", "highpass", "lowpass"])
def test_auto_adds_series_factors_many_seeds(kind, path, seed):
    auto_fixes_factor(kind, path, seed)


def test_more_order_fixes_an_under_modelled_model():
    session, model = effect_case("ff", 3, ("resonance:800,5,8",))
    result = refine(model, session.noise, session.sweeps, "under-modelled", TEST_REFIT)
    assert result.before.ratio > 3
    assert result.after.ratio <= 1.2 and result.model.order == model.order + 2


def test_auto_on_a_clean_session_changes_nothing():
    session, model = effect_case("ff", 3, ())
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    assert auto.steps == [] and auto.model is model
    assert auto.stop_reason == "at the floor"


@pytest.mark.parametrize("spec, message", [
    ("wobble", "unknown effect 'wobble'"),
    ("delay:x", "'x' is not a number"),
    ("time-variation", "time-variation is not a model structure"),
    ("clipping", "no recording clips"),
    ("resonance", "the sweeps show no resonance"),
    ("highpass:order=2", "the sweeps show no highpass"),
])
def test_bad_refinements_are_refused(spec, message):
    session, model = effect_case("ff", 3, ())
    with pytest.raises(HelmetAncError, match=message):
        refine(model, session.noise, session.sweeps, spec, TEST_REFIT)


class TestCommandLine:
    @pytest.fixture(scope="class")
    def files(self, tmp_path_factory):
        session, model = effect_case("ff", 5, ("delay:23",))
        folder = tmp_path_factory.mktemp("refine_cli")
        files = write_session(session, folder)
        model.save(folder / "model.json")
        files["model"] = folder / "model.json"
        return files

    def args(self, files, *extra):
        return ["--noise", str(files["noise"]), "--sweep", str(files["sweep1"]), "--sweep", str(files["sweep2"]), *extra]

    @pytest.mark.parametrize("extra, message", [
        (["--add", "delay:0"], "samples must be between 1"),
        (["--add", "wobble"], "unknown effect"),
        ([], "give --add"),
        (["--add", "delay:5", "--auto"], "not both"),
    ])
    def test_bad_input_is_one_line_exit_2_no_file(self, files, tmp_path, capsys, extra, message):
        out = tmp_path / "new.json"
        code = main(["refine", str(files["model"]), *self.args(files, *extra), "-o", str(out)])
        err = capsys.readouterr().err
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1
        assert not out.exists()

    def test_missing_model_file(self, files, tmp_path, capsys):
        out = tmp_path / "new.json"
        code = main(["diagnose", str(tmp_path / "absent.json"), *self.args(files)])
        assert code == 2 and "cannot read model" in capsys.readouterr().err

    def test_compare_and_diagnose_write_json(self, files, tmp_path, capsys):
        assert main(["compare", str(files["model"]), "--sweep", str(files["sweep1"]), "--sweep", str(files["sweep2"]),
                     "--json", str(tmp_path / "c.json")]) == 0
        assert main(["diagnose", str(files["model"]), *self.args(files), "--json", str(tmp_path / "d.json")]) == 0
        assert "delay" in capsys.readouterr().out
        assert (tmp_path / "c.json").exists() and (tmp_path / "d.json").exists()

    def test_refine_add_writes_the_refined_model(self, files, tmp_path, capsys):
        out = tmp_path / "new.json"
        assert main(["refine", str(files["model"]), *self.args(files, "--add", "delay:23"), "-o", str(out)]) == 0
        model = Model.load(out)
        assert model.delay in (22, 23) and model.history[-1]["effect"] == "delay"
        assert "noise floor" in capsys.readouterr().out

    def test_simulate_records_effects(self, tmp_path, capsys):
        assert main(["simulate", str(tmp_path / "s"), "--noise-seconds", "4", "--sweep-seconds", "0.5",
                     "--effect", "delay:5", "--effect", "periodic-disturbance:60"]) == 0
        assert "periodic-disturbance" in (tmp_path / "s" / "truth.json").read_text()
        assert main(["simulate", str(tmp_path / "t"), "--effect", "wobble"]) == 2
        assert not (tmp_path / "t").exists()


def test_steps_are_typed_records_with_a_json_round_trip():
    session, model, result = refined("ff", 5, "delay:23", "delay")
    step = result.step
    assert isinstance(step, RefinementStep) and step.effect == "delay"
    again = RefinementStep.from_dict(json.loads(json.dumps(step.to_dict())))
    assert again == step
    assert result.model.history[-1] == step.to_dict()


@pytest.mark.parametrize("effects", [("delay:23", "input-nonlinearity:-35,-35"),
                                     ("dc-offset:0.01", "clock-drift:40", "periodic-disturbance:50,2,1e-3")])
def test_auto_is_monotone_bounded_and_says_why_it_stopped(effects):
    session, model = effect_case("ff", 6, effects)
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    text = format_refinement(auto.steps, auto.stop_reason)
    assert len(auto.steps) <= 8
    kept = [s for s in auto.steps if s.accepted]
    for step in kept:
        if step.effect != "dc-offset":  # an offset lives at DC, outside the validation band
            assert step.rms_after < step.rms_before, text
    for i, step in enumerate(auto.steps):
        if not step.accepted:
            # A rejected effect stays rejected, except that it is tried once more after a later
            # accepted step changed the model (e.g. the delay it was judged without).
            later = [k for k in range(i + 1, len(auto.steps)) if auto.steps[k].effect == step.effect]
            assert len(later) <= 1, text
            assert all(any(s.accepted for s in auto.steps[i + 1:k]) for k in later), text
    assert max(sum(s.effect == e for s in auto.steps) for e in {s.effect for s in auto.steps}) <= 2, text
    # No step repeats: the same effect and parameters from the same model (its order and rms).
    keys = [(s.effect, json.dumps(s.params, sort_keys=True), s.order_before, s.rms_before) for s in auto.steps]
    assert len(keys) == len(set(keys)), text
    assert auto.stop_reason.split(";")[0] in ("at the floor", "nothing left that lowers the error") \
        or auto.stop_reason.startswith("effects that cannot be modelled"), text
    assert auto.after.ratio <= 1.2, text
    assert [h["effect"] for h in auto.model.history] == [s.effect for s in kept]
    assert f"stopped: {auto.stop_reason}" in text


def test_excluded_stretches_are_filled_with_the_models_prediction():
    # Identification on a model with excluded stretches sees the model's own prediction there
    # (missing data), the measured samples everywhere else; nothing is cut out.
    from sysid.io.corrections import excluded_mask
    from sysid.refits.machinery import _prepared
    session, model = effect_case("ff", 5, ())
    sweep = session.sweeps[0]
    excluded = {Path(sweep.path).name: [[0.5, 0.6], [1.0, 1.01]]}
    trial = Model(**{**model.__dict__, "excluded": excluded})
    prepared = _prepared(trial, sweep)
    mask = excluded_mask(sweep, excluded)
    assert prepared.y.size == sweep.y.size and mask.sum() == round(0.11 * sweep.fs)
    assert np.array_equal(prepared.y[~mask], sweep.y[~mask])
    assert np.allclose(prepared.y[mask], model.simulate(sweep.u)[mask])


def test_a_refit_whose_warm_start_reaches_the_floor_skips_the_re_identification():
    from sysid.refits.machinery import WARM_ENOUGH, _refit
    session, model = effect_case("ff", 5, ())
    assert compare(model, session.sweeps).ratio <= WARM_ENOUGH

    def reidentify():
        raise AssertionError("re-identified although a trial was at the floor")
    assert _refit(session.sweeps, [model], reidentify) is model
    worse = Model(**{**model.__dict__, "delay": model.delay + 5})
    assert _refit(session.sweeps, [worse], lambda: model) is model


def test_auto_applies_the_pending_data_corrections_together_before_one_re_identification():
    # The README's rig, short: an ear clock 60 ppm fast, a preamplifier clipping at 0.4 FS and an
    # offset. One step names all three (the clock first) and ends at the floor at the path's order.
    session, model = effect_case("ff", 7, ("clock-drift:60", "clipping:1.4,0.4", "dc-offset:0.01"))
    auto = refine_auto(model, session.noise, session.sweeps, TEST_REFIT)
    text = format_refinement(auto.steps, auto.stop_reason)
    first = auto.steps[0]
    assert first.effect == "clock-drift+clipping+dc-offset" and first.accepted, text
    assert first.params["ppm"] == pytest.approx(60.0, rel=0.02) and first.params["offset_fs"] == pytest.approx(0.01, rel=0.05)
    assert max(first.params["excluded_fraction"]) > 0.1, text
    assert auto.after.ratio <= 1.2 and auto.model.order <= model.order + 2, text
    assert auto.model.history[0]["effect"] == first.effect


def test_refine_corrections_refuses_a_structure():
    from sysid.core.effect_spec import EffectSpec
    from sysid.refine import refine_corrections
    session, model = effect_case("ff", 3, ())
    with pytest.raises(HelmetAncError, match="delay: not a data correction"):
        refine_corrections(model, session.noise, session.sweeps, [EffectSpec("delay", {"samples": 3})], TEST_REFIT)
