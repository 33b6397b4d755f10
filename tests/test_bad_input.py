"""Every bad input of tests/bad_inputs.py: exit 2, exactly one line on stderr, no traceback, no file touched."""

import pytest

from helmet_anc.cli import main
from bad_inputs import CASES, argv_of, prepare, snapshot


@pytest.fixture(scope="module")
def bad_files(session_files, identifications, tmp_path_factory):
    folder = tmp_path_factory.mktemp("bad_inputs")
    model_file = folder / "source_model.json"
    identifications["ff"].model.save(model_file)
    files = prepare(folder / "inputs", session_files, model_file)
    return folder / "inputs", files


@pytest.mark.parametrize("case", CASES, ids=[c.label for c in CASES])
def test_bad_input_is_one_line_exit_2_and_touches_nothing(case, bad_files, capsys):
    folder, files = bad_files
    before = snapshot(folder)
    code = main(argv_of(case, files))
    out, err = capsys.readouterr()
    assert code == 2, (out, err)
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert case.expect in err, err
    assert "LinAlgError" not in out + err and "DLASCL" not in out
    assert snapshot(folder) == before


def test_a_delay_of_1e9_fails_fast(bad_files, capsys):
    import time

    _, files = bad_files
    started = time.process_time()
    main(["diagnose", files["delay"], "--noise", files["noise"], "--sweep", files["sweep1"], "--sweep", files["sweep2"]])
    capsys.readouterr()
    assert time.process_time() - started < 1.0


@pytest.mark.parametrize("path", ["fb", "ff"])
@pytest.mark.parametrize("plant", ["appendix-a", "random"])
def test_the_ear_channel_checks_accept_real_sessions(path, plant, tmp_path):
    """Quiet plants and FF sessions (two microphones) must pass the silent/uncorrelated ear checks."""
    from sysid.random_plant import random_session
    from sysid.recordings import load_recording
    from sysid.simulate import SessionSpec, simulate_session, write_session

    settings = dict(noise_duration=4.0, sweep_duration=1.0)
    for seed in (0, 3):
        session = (random_session(seed, path, **settings) if plant == "random"
                   else simulate_session(SessionSpec(path=path, seed=seed, **settings)))
        files = write_session(session, tmp_path / f"{seed}")
        for key in ("noise", "sweep1", "sweep2"):
            assert load_recording(files[key]).y.size > 0


def test_a_recording_too_large_for_memory_is_refused_before_reading(tmp_path):
    from sysid.errors import RecordingError
    from sysid.recordings import MAX_RECORDING_BYTES, load_recording

    huge = tmp_path / "huge.wav"
    with open(huge, "wb") as handle:
        handle.truncate(MAX_RECORDING_BYTES + 1)  # sparse: no disk space used
    with pytest.raises(RecordingError, match="above the limit"):
        load_recording(huge)
