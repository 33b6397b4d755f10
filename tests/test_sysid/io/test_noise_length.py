"""sysid.io.recordings.check_noise_length: one rule for how long a noise recording must be, shared by identify,
diagnose and report (API and command line), and by ``simulate --noise-seconds``; one message naming the file."""

import re

import pytest
import scipy.io.wavfile

from helmet_anc.cli import main
from report import write_report
from sysid.core.errors import RecordingError
from sysid.core.plants import appendix_a_model
from sysid.core.thresholds import NOISE_AFTER_TRANSIENT_S, TRANSIENT_S
from sysid.diagnose import diagnose
from sysid.identify import identify
from sysid.io.recordings import Recording, check_noise_length, load_recording, noise_length_rule

RULE = re.escape(noise_length_rule())


def cut(session_files, folder, seconds: float | None = None, truncated: bool = False):
    """The session's noise recording cut to ``seconds``, or a WAV whose header promises 20 s and whose data
    end after 2 s (a copy interrupted)."""
    fs, data = scipy.io.wavfile.read(session_files["noise"])
    if truncated:
        path = folder / "noise_truncated.wav"
        path.write_bytes(session_files["noise"].read_bytes()[:44 + 4 * int(2.0 * fs)])
        return path
    path = folder / f"noise_{seconds:g}s.wav"
    scipy.io.wavfile.write(path, fs, data[:int(round(seconds * fs))])
    return path


def test_the_rule_is_the_transient_plus_what_the_detectors_compare():
    assert noise_length_rule().startswith(f"more than {TRANSIENT_S + NOISE_AFTER_TRANSIENT_S:g} s (its first "
                                          f"{TRANSIENT_S:g} s are the excitation's start-up")


@pytest.mark.parametrize("seconds", [0.5, 2.0, 3.04, 3.5, TRANSIENT_S + NOISE_AFTER_TRANSIENT_S])
def test_a_noise_recording_not_longer_than_the_rule_is_refused(seconds, rng):
    u = 0.1 * rng.standard_normal(int(seconds * 44100))
    with pytest.raises(RecordingError, match=rf"^short: a noise recording of {seconds:.3g} s is too short; it needs "
                                             rf"{RULE}$"):
        check_noise_length(Recording(u, 0.5 * u, 44100.0, "short"))


@pytest.mark.parametrize("case", ["0.5 s", "2 s", "truncated"])
def test_identify_diagnose_and_report_refuse_it_alike_from_python(case, session_files, sessions, tmp_path):
    path = cut(session_files, tmp_path, truncated=True) if case == "truncated" else cut(session_files, tmp_path,
                                                                                         float(case.split()[0]))
    noise = load_recording(path)
    sweeps = sessions["ff"].sweeps
    model = appendix_a_model("ff")
    message = rf"{re.escape(str(path))}: a noise recording of \S+ s is too short; it needs {RULE}"
    for run in (lambda: identify(noise, sweeps, "ff"), lambda: diagnose(model, noise, sweeps),
                lambda: write_report(tmp_path / "r.html", model, noise, sweeps)):
        with pytest.raises(RecordingError, match=message):
            run()
    assert not (tmp_path / "r.html").exists()


@pytest.mark.parametrize("command, case", [("identify", "0.5 s"), ("identify", "2 s"), ("identify", "truncated"),
                                           ("diagnose", "2 s"), ("report", "truncated")])
def test_the_command_line_gives_one_line_and_exit_2(command, case, session_files, tmp_path, capsys):
    noise = cut(session_files, tmp_path, truncated=True) if case == "truncated" else cut(session_files, tmp_path,
                                                                                         float(case.split()[0]))
    appendix_a_model("ff").save(tmp_path / "model.json")
    recordings = ["--noise", str(noise), "--sweep", str(session_files["sweep1"]), "--sweep", str(session_files["sweep2"])]
    argv = {"identify": ["identify", *recordings, "--path", "ff", "-o", str(tmp_path / "m.json")],
            "diagnose": ["diagnose", str(tmp_path / "model.json"), *recordings],
            "report": ["report", str(tmp_path / "model.json"), *recordings, "-o", str(tmp_path / "r.html")]}[command]
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(argv) == 2
    _, err = capsys.readouterr()
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert f"it needs {noise_length_rule()}" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_simulate_says_what_a_noise_recording_needs(tmp_path, capsys):
    assert main(["simulate", str(tmp_path / "s"), "--noise-seconds", "3.04"]) == 2
    _, err = capsys.readouterr()
    assert err == f"helmet-anc simulate: error: --noise-seconds 3.04: a noise recording needs {noise_length_rule()}\n"
    assert not (tmp_path / "s").exists()
