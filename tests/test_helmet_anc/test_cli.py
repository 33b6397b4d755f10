"""The helmet-anc command line: end to end on files, and one-line errors with exit status 2."""

import json

import numpy as np
import pytest
import scipy.io.wavfile
from repo import REPO

from helmet_anc.cli import main
from sysid.core.model import Model
from sysid.io.recordings import write_wav16


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _identify_args(files, output, *extra):
    return ["identify", "--noise", files["noise"], "--sweep", files["sweep1"], "--sweep", files["sweep2"], "--path", "ff",
            "--gammas", "50:1000:150", "--orders", "1:8", "-o", output, *extra]


def test_simulate_writes_a_session_with_truth(tmp_path, capsys):
    code, out, _ = _run(capsys, "simulate", tmp_path / "s", "--path", "ff", "--seed", "3", "--noise-seconds", "4",
                        "--sweep-seconds", "0.5")
    assert code == 0
    truth = json.loads((tmp_path / "s" / "truth.json").read_text())
    assert truth["spec"]["path"] == "ff" and truth["spec"]["seed"] == 3 and truth["effects"] == []
    assert Model.from_dict(truth["plant"]).order == 5
    fs, data = scipy.io.wavfile.read(tmp_path / "s" / "noise.wav")
    assert fs == 44100 and data.dtype == np.int16 and data.shape == (4 * 44100, 2)
    assert np.abs(data).max() < 32767  # nothing clips


def test_identify_end_to_end(session_files, tmp_path, capsys):
    code, out, err = _run(capsys, *_identify_args(session_files, tmp_path / "m.json", "--mat", tmp_path / "m.mat"))
    assert code == 0, err
    assert "chosen model" in out and "stable" in out
    model = Model.load(tmp_path / "m.json")
    assert model.stable and model.path == "ff"
    table = (tmp_path / "m.grid.csv").read_text().splitlines()
    assert table[0] == "gamma,order,stable,rms,chosen"
    assert len(table) == 1 + 7 * 8
    assert sum(line.endswith(",1") for line in table[1:]) == 1
    assert (tmp_path / "m.mat").exists()


def _assert_one_line_error(code, err, pattern):
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert pattern in err


class TestBadInput:
    def test_mono_file(self, session_files, tmp_path, capsys):
        scipy.io.wavfile.write(tmp_path / "mono.wav", 44100, np.ones(1000, np.int16))
        files = dict(session_files, noise=tmp_path / "mono.wav")
        code, _, err = _run(capsys, *_identify_args(files, tmp_path / "m.json"))
        _assert_one_line_error(code, err, "mono.wav: mono file")
        assert not (tmp_path / "m.json").exists()

    def test_wrong_channel(self, session_files, tmp_path, capsys):
        code, _, err = _run(capsys, *_identify_args(session_files, tmp_path / "m.json", "--output-channel", "5"))
        _assert_one_line_error(code, err, "output channel 5 does not exist")

    def test_corrupt_header(self, session_files, tmp_path, capsys):
        (tmp_path / "bad.wav").write_bytes(b"RIFF\x00\x00\x00\x00WAVEfmt ")
        code, _, err = _run(capsys, *_identify_args(dict(session_files, sweep1=tmp_path / "bad.wav"), tmp_path / "m.json"))
        _assert_one_line_error(code, err, "bad.wav: not a readable WAV file")

    def test_nan_samples(self, session_files, tmp_path, capsys):
        x = np.zeros((5000, 2), np.float32)
        x[:, 0] = 0.1
        x[7, 1] = np.inf
        scipy.io.wavfile.write(tmp_path / "inf.wav", 44100, x)
        code, _, err = _run(capsys, *_identify_args(dict(session_files, sweep2=tmp_path / "inf.wav"), tmp_path / "m.json"))
        _assert_one_line_error(code, err, "inf.wav: output channel has NaN or infinite samples")

    def test_silent_input(self, session_files, tmp_path, capsys):
        write_wav16(tmp_path / "silent.wav", np.zeros(5000), np.full(5000, 0.1), 44100)
        code, _, err = _run(capsys, *_identify_args(dict(session_files, noise=tmp_path / "silent.wav"), tmp_path / "m.json"))
        _assert_one_line_error(code, err, "silent.wav: input channel is silent")

    def test_too_short_after_transient(self, session_files, tmp_path, capsys):
        rng = np.random.default_rng(0)
        u = 0.1 * rng.standard_normal(3 * 44100 + 1000)
        write_wav16(tmp_path / "short.wav", u, 0.5 * u, 44100)
        code, _, err = _run(capsys, *_identify_args(dict(session_files, noise=tmp_path / "short.wav"), tmp_path / "m.json"))
        _assert_one_line_error(code, err, "short.wav: a noise recording of 3.02 s is too short; it needs more than 3.8 s")

    def test_sample_rate_mismatch(self, session_files, tmp_path, capsys):
        fs, data = scipy.io.wavfile.read(session_files["sweep2"])
        scipy.io.wavfile.write(tmp_path / "s48.wav", 48000, data)
        code, _, err = _run(capsys, *_identify_args(dict(session_files, sweep2=tmp_path / "s48.wav"), tmp_path / "m.json"))
        _assert_one_line_error(code, err, "s48.wav: sample rate 48000 Hz differs from 44100 Hz")

    def test_missing_output_folder(self, session_files, tmp_path, capsys):
        code, _, err = _run(capsys, *_identify_args(session_files, tmp_path / "no" / "m.json"))
        _assert_one_line_error(code, err, "does not exist")

    def test_bad_grid_ranges(self, session_files, tmp_path, capsys):
        code, _, err = _run(capsys, *_identify_args(session_files, tmp_path / "m.json")[:-2], "--orders", "5:2", "-o", tmp_path / "m.json")
        _assert_one_line_error(code, err, "--orders needs 1 <= A <= B")
        code, _, err = _run(capsys, *_identify_args(session_files, tmp_path / "m.json")[:-2], "--gammas", "a:b", "-o", tmp_path / "m.json")
        _assert_one_line_error(code, err, "--gammas must look like A:B:STEP")

    def test_one_sweep_only(self, session_files, tmp_path, capsys):
        args = ["identify", "--noise", session_files["noise"], "--sweep", session_files["sweep1"], "-o", tmp_path / "m.json"]
        code, _, err = _run(capsys, *args)
        _assert_one_line_error(code, err, "give --sweep exactly twice")

    def test_unknown_option_is_one_line(self, capsys):
        with pytest.raises(SystemExit) as exit_info:
            main(["identify", "--bogus"])
        assert exit_info.value.code == 2
        assert capsys.readouterr().err.count("\n") == 1


def test_clipping_is_reported_as_a_warning_not_an_error(session_files, tmp_path, capsys):
    fs, data = scipy.io.wavfile.read(session_files["sweep1"])
    data = data.copy()
    data[20000:20010, 1] = 32767
    scipy.io.wavfile.write(tmp_path / "clipped.wav", fs, data)
    code, out, err = _run(capsys, *_identify_args(dict(session_files, sweep1=tmp_path / "clipped.wav"), tmp_path / "m.json"))
    assert code == 0
    assert "helmet-anc: warning: " in err and "clipped.wav: output channel clipped" in err


def test_identify_report_to_a_missing_folder_is_refused_before_any_work(session_files, tmp_path, capsys):
    code, _, err = _run(capsys, *_identify_args(session_files, tmp_path / "m.json", "--report", tmp_path / "nowhere" / "r.html"))
    _assert_one_line_error(code, err, "does not exist")
    assert not (tmp_path / "m.json").exists()


def test_identify_writes_its_report_into_a_folder(session_files, tmp_path, capsys):
    (tmp_path / "reports").mkdir()
    code, out, err = _run(capsys, *_identify_args(session_files, tmp_path / "m.json", "--report", tmp_path / "reports"))
    assert code == 0, err
    html = (tmp_path / "reports" / "ff-report.html").read_text()
    assert html.count("<img") >= 10 and "http://" not in html and "https://" not in html


@pytest.mark.parametrize("command", [["helmet_anc.cli", "generate-firmware"], ["helmet_anc.firmware_cli"]])
def test_output_into_a_closed_pipe_ends_quietly(command, tmp_path):
    """``generate-firmware ... | head``: the reader is gone before the summary is printed; no traceback."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    from helmet_anc.pipes import EXIT_BROKEN_PIPE
    from sysid.core.plants import appendix_a_model

    appendix_a_model("ff").save(tmp_path / "ff.json")
    root = str(REPO)
    process = subprocess.Popen([sys.executable, "-m", *command, str(tmp_path / "ff.json"), "-o", str(tmp_path / "fw"),
                                "--variant", "float", "-q"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               env={**os.environ, "PYTHONPATH": root}, cwd=tmp_path)
    process.stdout.close()  # as head does once it has its lines
    err = process.stderr.read().decode()
    assert process.wait(timeout=300) == EXIT_BROKEN_PIPE, err
    assert err == ""
    assert (tmp_path / "fw" / "manifest.json").is_file()  # written whole before anything was printed


@pytest.mark.parametrize("value", ["0", "-4", "2.5", "many"])
def test_identify_refuses_a_bad_max_order(session_files, tmp_path, capsys, value):
    code, _, err = _run(capsys, *_identify_args(session_files, tmp_path / "m.json", "--max-order", value))
    _assert_one_line_error(code, err, "--max-order must be a whole number of states")
    assert not (tmp_path / "m.json").exists()


def test_identify_keeps_the_model_under_max_order_and_prints_the_curve(session_files, tmp_path, capsys):
    code, out, err = _run(capsys, *_identify_args(session_files, tmp_path / "m.json", "--max-order", "3"))
    assert code == 0, err
    model = Model.load(tmp_path / "m.json")
    assert model.order <= 3 and model.identification["max_order"] == 3
    assert "order/error/cost" in out and "*" + str(model.order) in out
