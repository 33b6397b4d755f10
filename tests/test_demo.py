"""``helmet-anc demo``: the whole job with no arguments but a folder."""

import json

import pytest

from helmet_anc.cli import main
from sysid.model import Model


def test_demo_refuses_a_file_as_its_folder(tmp_path, capsys):
    target = tmp_path / "taken"
    target.write_text("not a folder")
    assert main(["demo", str(target)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "exists and is not a folder" in err
    assert target.read_text() == "not a folder"


@pytest.mark.slow
def test_demo_identifies_both_paths_and_verifies_their_firmware(tmp_path, capsys):
    assert main(["demo", str(tmp_path / "demo")]) == 0
    out = capsys.readouterr().out
    for path in ("fb", "ff"):
        model = Model.load(tmp_path / "demo" / f"{path}_model.json")
        assert model.stable
        assert model.identification["rms"] < 1.2 * model.identification["noise_floor"]
        manifest = json.loads((tmp_path / "demo" / "firmware" / path / "manifest.json").read_text())
        assert all(row["q15"]["max_lsb_difference"] == 0 for row in manifest["verification"]["sweeps"])
    assert "0 LSB" in out
