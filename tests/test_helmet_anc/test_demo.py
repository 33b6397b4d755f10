"""``helmet-anc demo``: the whole job with no arguments but a folder."""

import json

import pytest

from helmet_anc.cli import main
from sysid.core.model import Model


def test_demo_refuses_a_file_as_its_folder(tmp_path, capsys):
    target = tmp_path / "taken"
    target.write_text("not a folder")
    assert main(["demo", str(target)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "exists and is not a folder" in err
    assert target.read_text() == "not a folder"


def test_demo_refuses_a_folder_of_files_it_did_not_write_before_any_work(tmp_path, capsys):
    target = tmp_path / "work"
    target.mkdir()
    (target / "fb_model.json").write_text('{"format": "helmet-anc/model@1"}')  # a name the demo writes
    (target / "notes.txt").write_text("mine")
    assert main(["demo", str(target)]) == 2
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1 and "did not write (fb_model.json, notes.txt)" in captured.err
    assert "--force" in captured.err and captured.out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["work"]
    assert sorted(p.name for p in target.iterdir()) == ["fb_model.json", "notes.txt"]


@pytest.mark.slow
def test_demo_rerun_replaces_only_its_own_files(tmp_path, capsys):
    """A second demo into the first one's folder, with a file of the user's there (--force): that file stays."""
    out = tmp_path / "demo"
    args = ["demo", str(out), "--no-firmware", "--no-report"]
    assert main(args) == 0
    first = json.loads((out / "demo-manifest.json").read_text())["files"]
    assert "fb_model.json" in first and "ff/noise.wav" in first
    (out / "notes.txt").write_text("mine")
    assert main(args) == 2 and "notes.txt" in capsys.readouterr().err
    assert main(args + ["--force"]) == 0
    assert (out / "notes.txt").read_text() == "mine"
    assert json.loads((out / "demo-manifest.json").read_text())["files"].keys() == first.keys()


@pytest.mark.slow
def test_demo_identifies_both_paths_and_verifies_their_firmware(tmp_path, capsys):
    assert main(["demo", str(tmp_path / "demo")]) == 0
    captured = capsys.readouterr()
    out = captured.out
    for path in ("fb", "ff"):
        model = Model.load(tmp_path / "demo" / f"{path}_model.json")
        assert model.stable
        assert model.identification["rms"] < 1.2 * model.identification["noise_floor"]
        manifest = json.loads((tmp_path / "demo" / "firmware" / path / "manifest.json").read_text())
        assert all(row["q15"]["max_lsb_difference"] == 0 for row in manifest["verification"]["sweeps"])
    assert "0 LSB" in out
    steps = [line for line in captured.err.splitlines() if line.startswith("demo [")]
    assert [line.split("]")[0] for line in steps] == [f"demo [{k}/6" for k in range(1, 7)]


@pytest.mark.parametrize("report, firmware, total", [(True, True, 6), (False, True, 5), (True, False, 4),
                                                      (False, False, 3)])
def test_the_step_lines_count_the_steps_that_run(report, firmware, total, capsys):
    from helmet_anc.commands.demo import _Steps, step_count

    assert step_count(report, firmware) == total
    say = _Steps(quiet=False, total=total)
    for k in range(total):
        say(f"step {k}")
    lines = capsys.readouterr().err.splitlines()
    assert [line.split("]")[0] for line in lines] == [f"demo [{k}/{total}" for k in range(1, total + 1)]
    assert all(line.endswith(" s)") for line in lines)
