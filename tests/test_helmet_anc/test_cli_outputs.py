"""The command line never loses a user's data: -o checks, output folders, Ctrl-C; and the expected interfaces."""

import json
import os
import pty
import select
import signal
import subprocess
import sys
import time

import pytest
from repo import REPO as REPO_ROOT

from codegen.api import MANIFEST_FORMAT
from helmet_anc.cli import EXAMPLES, build_parser, main
from sysid.core.files import read_manifest
from sysid.core.model import Model

REPO = str(REPO_ROOT)


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _snapshot(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def model_file(identifications, tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "ff_model.json"
    identifications["ff"].model.save(path)
    return path


def _sweeps(files):
    return ["--sweep", files["sweep1"], "--sweep", files["sweep2"]]


def test_version_and_generate_firmware_help(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.startswith("helmet-anc 0.")
    with pytest.raises(SystemExit) as exit_info:
        main(["generate-firmware", "--help"])
    out, err = capsys.readouterr()
    assert exit_info.value.code == 0 and err == ""
    assert "usage: helmet-anc generate-firmware" in out and "--force" in out and "example:" in out


def test_every_subcommand_help_shows_an_example():
    parser = build_parser()
    commands = next(a for a in parser._actions if a.dest == "command").choices
    missing = [name for name, sub in commands.items() if "example: helmet-anc " + name not in sub.format_help()]
    assert not missing, f"no example in the help of {missing} (add one to helmet_anc.cli.EXAMPLES)"
    assert set(EXAMPLES) >= set(commands)


def test_output_may_not_be_an_input(session_files, model_file, tmp_path, capsys):
    before = session_files["sweep1"].read_bytes()
    code, out, err = _run(capsys, "compare", model_file, *_sweeps(session_files), "--json", session_files["sweep1"],
                          "--force")
    assert code == 2 and err.count("\n") == 1 and "is an input" in err
    assert session_files["sweep1"].read_bytes() == before
    text = model_file.read_text()
    code, _, err = _run(capsys, "compare", model_file, *_sweeps(session_files), "--json", model_file)
    assert code == 2 and "is an input" in err and model_file.read_text() == text


def test_a_file_not_ours_is_kept_unless_force(session_files, model_file, tmp_path, capsys):
    target = tmp_path / "notes.json"
    target.write_text('{"mine": true}')
    code, _, err = _run(capsys, "compare", model_file, *_sweeps(session_files), "--json", target)
    assert code == 2 and "--force" in err and target.read_text() == '{"mine": true}'
    code, _, err = _run(capsys, "compare", model_file, *_sweeps(session_files), "--json", target, "--force")
    assert code == 0, err
    assert json.loads(target.read_text())["format"] == "helmet-anc/comparison@1"
    # Our own output may be written again without --force.
    code, _, err = _run(capsys, "compare", model_file, *_sweeps(session_files), "--json", target)
    assert code == 0, err


def test_output_location_is_checked_before_any_work(session_files, tmp_path, capsys):
    started = time.process_time()
    code, _, err = _run(capsys, "identify", "--noise", session_files["noise"], *_sweeps(session_files),
                        "-o", tmp_path / "missing" / "m.json")
    assert code == 2 and "does not exist" in err
    assert time.process_time() - started < 0.5  # refused before loading or fitting anything


def test_simulate_refuses_a_folder_with_user_recordings(tmp_path, capsys):
    folder = tmp_path / "s"
    folder.mkdir()
    (folder / "noise.wav").write_bytes(b"the user's own recording")
    code, _, err = _run(capsys, "simulate", folder, "--noise-seconds", "4", "--sweep-seconds", "0.5")
    assert code == 2 and "--force" in err
    assert (folder / "noise.wav").read_bytes() == b"the user's own recording"


def test_generate_firmware_never_deletes_user_files(model_file, tmp_path, capsys):
    folder = tmp_path / "fw"
    code, _, err = _run(capsys, "generate-firmware", model_file, "-o", folder)
    assert code == 0, err
    assert read_manifest(folder, "manifest.json", MANIFEST_FORMAT) is not None
    code, _, err = _run(capsys, "generate-firmware", model_file, "-o", folder)  # our previous output: replaced
    assert code == 0, err
    (folder / "main.c").write_text("int main(void) { return 0; }\n")
    before = _snapshot(folder)
    code, _, err = _run(capsys, "generate-firmware", model_file, "-o", folder, "--name", "other")
    assert code == 2 and err.count("\n") == 1 and "main.c" in err
    assert _snapshot(folder) == before
    code, _, err = _run(capsys, "generate-firmware", model_file, "-o", folder, "--name", "other", "--force")
    assert code == 0, err
    assert sorted(p.name for p in folder.iterdir()) == ["main.c", "manifest.json", "other_filter.c", "other_filter.h"]


def test_generate_firmware_refuses_the_project_firmware_folder(model_file, capsys):
    firmware = os.path.join(REPO, "firmware")
    before = _snapshot(__import__("pathlib").Path(firmware))
    code, _, err = _run(capsys, "generate-firmware", model_file, "-o", firmware)
    assert code == 2 and err.count("\n") == 1 and "did not write" in err
    assert _snapshot(__import__("pathlib").Path(firmware)) == before


def _interrupt_after_progress(argv, cwd, timeout=240.0):
    """Run the CLI with stderr on a terminal; send SIGINT at its first progress draw. Return (code, stderr)."""
    master, slave = pty.openpty()
    # A test run started in the background of a non-interactive shell inherits SIGINT ignored, and
    # Python then installs no KeyboardInterrupt handler; a terminal's Ctrl-C finds it at its default.
    process = subprocess.Popen([sys.executable, "-m", "helmet_anc.cli", *map(str, argv)], cwd=cwd,
                               stdout=subprocess.DEVNULL, stderr=slave, stdin=subprocess.DEVNULL,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    os.close(slave)
    seen, sent = b"", False
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        ready, _, _ = select.select([master], [], [], 0.2)
        if ready:
            try:
                chunk = os.read(master, 4096)
            except OSError:
                break
            if not chunk:
                break
            seen += chunk
        if not sent and b"[" in seen:
            process.send_signal(signal.SIGINT)
            sent = True
        if process.poll() is not None and not ready:
            break
    code = process.wait(timeout=60)
    os.close(master)
    return code, sent, seen.decode(errors="replace")


def _no_partial_files(folder):
    return [p.name for p in folder.rglob("*") if ".partial" in p.name]


def test_ctrl_c_during_identify_exits_130_and_writes_nothing(session_files, tmp_path):
    code, sent, err = _interrupt_after_progress(
        ["identify", "--noise", session_files["noise"], *_sweeps(session_files), "--path", "ff",
         "-o", tmp_path / "m.json", "--mat", tmp_path / "m.mat"], cwd=REPO)
    assert sent, err
    assert code == 130, err
    assert "Traceback" not in err and err.rstrip().splitlines()[-1].endswith("interrupted; no partial output left")
    assert list(tmp_path.iterdir()) == []


def test_ctrl_c_during_generate_firmware_leaves_no_partial_folder(model_file, session_files, tmp_path):
    folder = tmp_path / "fw"
    code, sent, err = _interrupt_after_progress(
        ["generate-firmware", model_file, "-o", folder, "--verify", *_sweeps(session_files)], cwd=REPO)
    assert sent, err
    assert code in (0, 130), err  # 0 only if the interrupt came after the last file was in place
    assert "Traceback" not in err
    assert _no_partial_files(tmp_path) == [] and [p.name for p in tmp_path.iterdir()] in ([], ["fw"])
    if folder.exists():
        assert read_manifest(folder, "manifest.json", MANIFEST_FORMAT) is not None


def test_mat_export_has_the_ordinary_mode(tmp_path):
    umask = os.umask(0o022)
    try:
        Model(path="fb", fs=1000.0, A=[[0.5]], B=[[1.0]], C=[[1.0]], D=[[0.0]]).save_mat(tmp_path / "m.mat")
    finally:
        os.umask(umask)
    assert (tmp_path / "m.mat").stat().st_mode & 0o777 == 0o644
