"""``helmet-anc batch``: exit status 0 / 1 (failed sessions) / 2 (bad usage), progress on stderr."""

from __future__ import annotations

import csv
import shutil

import pytest

from helmet_anc.cli import main
from sysid.simulate import write_session
from sysid.random_plant import random_session
from tests.batch_sessions import SHORT_SESSION

FAST = ["--gammas", "10:1000:60", "--orders", "1:12"]


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli_sessions")
    session = random_session(3, "fb", **SHORT_SESSION)
    write_session(session, root / "H1" / "good")
    bad = write_session(session, root / "H1" / "bad")
    bad["sweep1"].write_bytes(b"not a wav file at all")
    return root


def test_bad_sessions_argument_is_usage_error_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["batch", str(tmp_path / "missing"), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("helmet-anc batch: error:") and "missing" in err[0]
    assert not out.exists()


def test_folder_not_ours_is_usage_error_and_left_as_it_was(sessions, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(["batch", str(sessions), "-o", str(out), "--workers", "1", *FAST]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "was not written by helmet-anc batch" in err[0] and "--force" in err[0]
    assert [p.name for p in out.iterdir()] == ["notes.txt"]


def test_workers_and_scheduler_together_refused(sessions, tmp_path, capsys):
    assert main(["batch", str(sessions), "-o", str(tmp_path / "o"), "--workers", "2", "--scheduler", "tcp://x:1"]) == 2
    assert "not both" in capsys.readouterr().err


def test_failed_session_gives_exit_1_with_the_count_and_a_resumable_folder(sessions, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["batch", str(sessions), "-o", str(out), "--workers", "1", *FAST]) == 1
    captured = capsys.readouterr()
    assert "[1/2]" in captured.err and "[2/2]" in captured.err
    assert "1 session(s) failed" in captured.err
    rows = {r["session"]: r for r in csv.DictReader((out / "results.csv").open())}
    assert rows["H1_good_fb"]["status"] == "ok"
    assert rows["H1_bad_fb"]["status"] == "failed" and "sweep1.wav" in rows["H1_bad_fb"]["reason"]
    assert (out / "summary.html").is_file() and (out / "models" / "H1_good_fb.json").is_file()

    # Rerun: the good session is taken from the first run, the bad one is tried again.
    assert main(["batch", str(sessions), "-o", str(out), "--workers", "1", *FAST]) == 1
    err = capsys.readouterr().err
    assert "H1_good_fb resumed" in err and "H1_bad_fb failed" in err


def test_all_ok_is_exit_0_and_a_folder_lacking_a_file_is_listed(sessions, tmp_path, capsys):
    only_good = tmp_path / "only"
    shutil.copytree(sessions / "H1" / "good", only_good / "H1" / "good")
    shutil.copytree(sessions / "H1" / "good", only_good / "H1" / "half")
    (only_good / "H1" / "half" / "noise.wav").unlink()
    assert main(["batch", str(only_good), "-o", str(tmp_path / "out"), "--workers", "1", *FAST]) == 0
    captured = capsys.readouterr()
    assert "1 session(s): 1 identified" in captured.out
    assert "1 folder(s) skipped: H1/half lacks noise.wav" in captured.out
    assert captured.err.splitlines()[0] == "skipped H1/half: lacks noise.wav"
