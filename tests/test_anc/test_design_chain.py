"""The README's chain: ``helmet-anc design ... -o controller.json`` then ``generate-firmware --controller
controller.json -o fw_control``, as written (the design's default latency is the board's)."""

from __future__ import annotations

import pytest
from control_cases import small_controller

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


@pytest.mark.slow
def test_the_readme_chain_runs_as_written(tmp_path, capsys, monkeypatch):
    """design (the seed's models, default latency, the default spectrum, at the README's --max-order 8: at the
    board-fitted orders the code generator still refuses the designed filters' sections) then generate-firmware,
    in one folder."""
    monkeypatch.chdir(tmp_path)
    appendix_a_model("fb").save(tmp_path / "fb_model.json")
    appendix_a_model("ff").save(tmp_path / "ff_model.json")
    assert main(["design", "--fb", "fb_model.json", "--ff", "ff_model.json", "--max-order", "8", "-o",
                 "controller.json"]) == 0
    printed = capsys.readouterr().out
    assert "positive = quieter at the ear" in printed and "causal ff" in printed
    controller = Controller.load(tmp_path / "controller.json")
    assert controller.latency_samples == BOARD_LATENCY_SAMPLES
    assert controller.limits is not None and controller.feedback_bound is not None
    assert firmware_main(["--controller", "controller.json", "-o", "fw_control", "-q"]) == 0
    assert (tmp_path / "fw_control" / "controller_config.h").is_file()


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
