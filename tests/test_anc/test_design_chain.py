"""The README's chain: ``helmet-anc design ... -o controller.json`` then ``generate-firmware --controller
controller.json -o fw_control``, as written (the design's default latency is the board's)."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
import scipy.signal
from control_cases import small_controller
from repo import REPO

from anc import Controller
from anc.controller import BOARD_LATENCY_SAMPLES
from helmet_anc.cli import main
from helmet_anc.firmware_cli import main as firmware_main
from sysid.core.plants import appendix_a_model


def test_a_controller_at_the_default_latency_generates_firmware(tmp_path, capsys):
    """A stored controller at the design's default latency is accepted by generate-firmware as written."""
    path = tmp_path / "controller.json"
    small_controller().save(path)
    assert firmware_main(["--controller", str(path), "-o", str(tmp_path / "fw_control"), "-q"]) == 0
    assert f"latency {BOARD_LATENCY_SAMPLES} samples" in capsys.readouterr().out
    assert (tmp_path / "fw_control" / "controller_config.h").is_file()


def test_a_variant_below_min_snr_is_left_out_in_one_line(tmp_path, capsys):
    """--min-snr between the variants' predictions (Q15 98.1 dB everywhere, float32 106.9-144.4 dB): the float32
    filters are written, the Q15 variant is named in one line with the filter that limits it, and building it
    stops with that reason; above both, the controller is refused in one line (exit 2) and nothing is written."""
    path = tmp_path / "controller.json"
    small_controller().save(path)
    assert firmware_main(["--controller", str(path), "-o", str(tmp_path / "fw"), "-q", "--min-snr", "100"]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if line]
    assert len(notes) == 1 and "q15 variant not generated (float written)" in notes[0]
    assert "internal model S: q15 variant refused: predicted SNR 98.1 dB" in notes[0]
    manifest = json.loads((tmp_path / "fw" / "manifest.json").read_text())
    assert manifest["variants"] == ["float"] and list(manifest["refused"]) == ["q15"]
    config = (tmp_path / "fw" / "controller_config.h").read_text()
    assert "#define CTL_HAS_Q15 0" in config and "#define CTL_HAS_F32 1" in config
    assert '#error "Q15 variant not generated' in config
    assert "ctl_w_f32_process" in (tmp_path / "fw" / "ctl_w_filter.c").read_text()
    assert "ctl_w_q15_step" not in (tmp_path / "fw" / "ctl_w_filter.c").read_text()
    assert firmware_main(["--controller", str(path), "-o", str(tmp_path / "none"), "-q", "--min-snr", "120"]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "refused: predicted SNR" in error[0]
    assert not (tmp_path / "none").exists()


@pytest.mark.slow
def test_the_readme_chain_runs_as_written(tmp_path, capsys, monkeypatch):
    """design (the seed's models, default latency, the default spectrum, the board-fitted default orders) then
    generate-firmware, in one folder: both variants of every filter written, none left out."""
    monkeypatch.chdir(tmp_path)
    appendix_a_model("fb").save(tmp_path / "fb_model.json")
    appendix_a_model("ff").save(tmp_path / "ff_model.json")
    assert main(["design", "--fb", "fb_model.json", "--ff", "ff_model.json", "-o", "controller.json"]) == 0
    printed = capsys.readouterr().out
    assert "positive = quieter at the ear" in printed and "causal ff" in printed
    controller = Controller.load(tmp_path / "controller.json")
    assert controller.latency_samples == BOARD_LATENCY_SAMPLES
    assert controller.limits is not None and controller.feedback_bound is not None
    assert firmware_main(["--controller", "controller.json", "-o", "fw_control", "-q"]) == 0
    assert "not generated" not in capsys.readouterr().err
    manifest = json.loads((tmp_path / "fw_control" / "manifest.json").read_text())
    assert manifest["variants"] == ["q15", "float"] and manifest["refused"] == {}
    assert (tmp_path / "fw_control" / "controller_config.h").is_file()


def _sweep(fs: float, seconds: float, model) -> np.ndarray:
    """Exponential sweep 20 Hz-4 kHz whose float64 output through ``model`` peaks at -1 dBFS."""
    t = np.arange(int(seconds * fs)) / fs
    s = scipy.signal.chirp(t, 20.0, t[-1], 4000.0, method="logarithmic")
    return s * min(1.0, 10 ** (-1.0 / 20) / np.max(np.abs(model.simulate(s))))


@pytest.mark.slow
def test_the_seed_pairs_designed_controller_runs_bit_exact_at_the_board_orders(tmp_path):
    """The seed pair's controller at the board-fitted orders (identified models, the road noise recorded with
    ANC off): generate-firmware keeps both variants of S, Q and W, each filter's host C equals its Python twin
    (Q15 to 0 LSB, float32 bit for bit) on a sweep, within --min-snr of the float64 filter, and the control
    path's host build equals its twin frame for frame in the closed loop on the true FB plant."""
    from anc.design import design
    from anc.disturbance import default_disturbance, from_recording, synthesize
    from codegen.api import generate_controller_firmware
    from codegen.build import host_filter
    from codegen.context import build_context
    from codegen.control_loop import board_loop
    from codegen.controller import FILTER_NAMES, plan_controller
    from codegen.reference import to_q15
    from codegen.render import render_files
    from codegen.verify import verify_host
    from control_cases import identified, recording_with_anc_off, seed_pair

    s_model, p_model = identified("seed")
    pair = seed_pair()
    controller = design(s_model, p_model, from_recording(recording_with_anc_off(pair.p), ff_model=p_model))
    manifest = generate_controller_firmware(controller, tmp_path / "fw")
    assert manifest.data["variants"] == ["q15", "float"] and manifest.data["refused"] == {}
    plan = plan_controller(controller)
    for part, sub in plan.plans.items():
        name = FILTER_NAMES[part]
        files = render_files(build_context(name=name, provenance=sub.provenance, fs=sub.realisation.fs,
                                           cascade=sub.cascade, variants=tuple(sub.predictions), fixed=sub.fixed,
                                           floating=sub.floating))
        for key, prediction in sub.predictions.items():
            assert prediction.snr_db >= 30.0, (name, key)
        verification = verify_host(sub, host_filter("cffi", name, files, sub.designs),
                                   [_sweep(controller.fs, 0.4, sub.model)])
        row = verification["sweeps"][0]
        assert row["q15"]["max_lsb_difference"] == 0, name
        assert row["float"]["bit_exact"], name
        assert min(row["q15"]["snr_vs_float64_db"], row["float"]["snr_vs_float64_db"]) >= 30.0, name
    x, u = synthesize(default_disturbance(controller.fs, pair.p), 1500, controller.fs, 0)
    d = pair.p.simulate(x) + u
    chin = to_q15(x)
    header = np.concatenate(([pair.s.order, pair.s.delay], np.ravel(pair.s.A), np.ravel(pair.s.B),
                             np.ravel(pair.s.C), np.ravel(pair.s.D)))
    for variant, flag in (("q15", ""), ("float", "-DANC_CONTROL_F32")):
        work = tmp_path / variant
        work.mkdir()
        header.astype(np.float64).tofile(work / "plant.f64")
        np.asarray(d, np.float64).tofile(work / "d.f64")
        np.asarray(chin, np.int16).tofile(work / "chin.q15")
        subprocess.run(["make", "-s", "-f", str(REPO / "firmware" / "Makefile"), "closed-loop-host",
                        f"CTL={tmp_path / 'fw'}", f"CONTROL={flag}"], cwd=work, check=True, capture_output=True,
                       timeout=300)
        subprocess.run([str(work / "build" / "closed_loop_host")], cwd=work, check=True, capture_output=True,
                       timeout=300)
        twin = board_loop(plan, pair.s, d, chin, variant)
        np.testing.assert_array_equal(np.fromfile(work / "ear.q15", np.int16), twin.ear)
        np.testing.assert_array_equal(np.fromfile(work / "drive.q15", np.int16), twin.drive)


@pytest.mark.slow
def test_the_designed_feedback_filter_holds_its_round_off_on_the_board():
    """Q designed on the seed's identified models at the board's orders has no pole nearer z = 1 than its
    basis's lowest corner allows, and neither board variant's round-off falls below generate-firmware's
    30 dB (poles within 2e-6 of z = 1, from corners at 3-5 Hz, gave 7-24 dB)."""
    import numpy as np

    from anc.design import design
    from anc.disturbance import from_recording
    from anc.feedback_bound import BASIS_HZ, DC_BLOCK_HZ
    from codegen.controller import _filter_model
    from codegen.plan import plan_firmware
    from control_cases import identified, recording_with_anc_off, seed_pair

    s_model, p_model = identified("seed")
    disturbance = from_recording(recording_with_anc_off(seed_pair().p), ff_model=p_model)
    controller = design(s_model, p_model, disturbance)
    lowest = min(BASIS_HZ[0], DC_BLOCK_HZ)
    # Balanced truncation may move a pole, not by an order of magnitude towards z = 1.
    closest = float(np.min(1.0 - np.abs(np.linalg.eigvals(controller.fb.A))))
    assert closest > 0.1 * 2.0 * np.pi * lowest / controller.fs
    plan = plan_firmware(_filter_model(controller.fb, controller.fs, "fb"), min_snr=-np.inf)
    for variant, prediction in plan.predictions.items():
        assert prediction.roundoff_snr_db >= 30.0, variant
