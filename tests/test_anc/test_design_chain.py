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
    """design (the seed's models, default latency, the default spectrum) then generate-firmware, in one folder."""
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
    assert (tmp_path / "fw_control" / "controller_config.h").is_file()
