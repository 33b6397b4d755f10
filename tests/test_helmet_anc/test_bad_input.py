"""Every bad input of tests/bad_inputs.py: exit 2, exactly one line on stderr, no traceback, no file touched."""

import pytest
from bad_inputs import CASES, argv_of, prepare, snapshot

from helmet_anc.cli import main
from sysid.core.plants import appendix_a_model


@pytest.fixture(scope="module")
def bad_files(session_files, tmp_path_factory):
    # A stable model of the session's path is all a case needs: the true plant costs no identification.
    folder = tmp_path_factory.mktemp("bad_inputs")
    model_file = folder / "source_model.json"
    appendix_a_model("ff").save(model_file)
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


def test_a_recording_too_large_for_memory_is_refused_before_reading(tmp_path):
    from sysid.core.errors import RecordingError
    from sysid.io.recordings import MAX_RECORDING_BYTES, load_recording

    huge = tmp_path / "huge.wav"
    with open(huge, "wb") as handle:
        handle.truncate(MAX_RECORDING_BYTES + 1)  # sparse: no disk space used
    with pytest.raises(RecordingError, match="above the limit"):
        load_recording(huge)
