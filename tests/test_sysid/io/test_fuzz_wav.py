"""Fuzzing WAV files (hypothesis): random RIFF headers and contents are loaded or refused in one line.

Property: ``load_recording`` returns a Recording or raises RecordingError (one line); the
command line (``compare``) exits 0 or exits 2 with exactly one line on stderr, and no file changes.
"""

import struct

import numpy as np
import pytest
from bad_inputs import snapshot
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from helmet_anc.cli import main
from sysid.core.errors import RecordingError
from sysid.io.recordings import load_recording


@st.composite
def wav_bytes(draw):
    """A RIFF/WAVE file whose header fields and data are drawn at random (sometimes consistent, often not)."""
    fmt_tag = draw(st.sampled_from([1, 3, 0xFFFE, 0, 2, 65535]))
    channels = draw(st.sampled_from([0, 1, 2, 3, 65535]))
    rate = draw(st.sampled_from([0, 1, 8000, 44100, 48000, 2**32 - 1]))
    bits = draw(st.sampled_from([0, 8, 16, 24, 32, 64, 7]))
    frames = draw(st.integers(0, 3000))
    block = max(channels * max(bits, 8) // 8, 1)
    if draw(st.booleans()) and bits in (16, 32) and fmt_tag in (1, 3):
        dtype = {(1, 16): "<i2", (1, 32): "<i4", (3, 32): "<f4"}.get((fmt_tag, bits), "<i2")
        samples = draw(st.sampled_from(["noise", "zeros", "nan", "rail"]))
        shape = (frames, max(channels, 1))
        rng = np.random.default_rng(frames)
        data = {"noise": rng.standard_normal(shape) * (0.1 if dtype == "<f4" else 3000),
                "zeros": np.zeros(shape), "nan": np.full(shape, np.nan),
                "rail": np.full(shape, 1e9)}[samples]
        payload = np.nan_to_num(data, nan=0).astype(dtype).tobytes() if dtype != "<f4" else data.astype(dtype).tobytes()
    else:
        payload = draw(st.binary(max_size=4000))
    data_size = draw(st.sampled_from([len(payload), 0, 2**32 - 1, len(payload) + 7]))
    fmt = struct.pack("<HHIIHH", fmt_tag, channels, rate, rate * block % 2**32, block % 2**16, bits)
    body = b"WAVE" + b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", data_size) + payload
    riff_size = draw(st.sampled_from([len(body), 0, 2**32 - 1]))
    blob = b"RIFF" + struct.pack("<I", riff_size) + body
    cut = draw(st.integers(0, len(blob)))
    return blob[:cut] if draw(st.integers(0, 4)) == 0 else blob


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(blob=wav_bytes())
def test_load_recording_returns_or_raises_recording_error(blob, tmp_path):
    path = tmp_path / "fuzz.wav"
    path.write_bytes(blob)
    try:
        recording = load_recording(path)
    except RecordingError as exc:
        assert "\n" not in str(exc)
        return
    assert recording.u.size == recording.y.size > 0 and np.all(np.isfinite(recording.u))


def _run_compare(blob, session_files, model_file, folder, capsys):
    sweep = folder / "fuzz.wav"
    sweep.write_bytes(blob)
    before = snapshot(folder)
    code = main(["compare", str(model_file), "--sweep", str(sweep), "--sweep", str(session_files["sweep2"])])
    _, err = capsys.readouterr()
    assert code in (0, 2)
    if code == 2:
        assert err.count("\n") == 1 and "Traceback" not in err, err
    assert snapshot(folder) == before


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    # The session's true plant: a stable model without the cost of an identification.
    from sysid.core.plants import appendix_a_model

    path = tmp_path_factory.mktemp("fuzz_wav") / "ff_model.json"
    appendix_a_model("ff").save(path)
    return path


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(blob=wav_bytes())
# One 8-bit frame at 1 Hz: its DC-offset warnings once came before the sample-rate error.
@example(blob=b"RIFF&\x00\x00\x00WAVEfmt \x10\x00\x00\x00\x01\x00\x02\x00\x01\x00\x00\x00\x02\x00\x00\x00"
              b"\x02\x00\x08\x00data\x02\x00\x00\x00\x00\x00")
# One 8-bit frame at 44.1 kHz: a sweep shorter than the start validation skips left nothing to validate.
@example(blob=b"RIFF&\x00\x00\x00WAVEfmt \x10\x00\x00\x00\x01\x00\x02\x00D\xac\x00\x00\x88X\x01\x00"
              b"\x02\x00\x08\x00data\x02\x00\x00\x00\x00\x00")
def test_compare_on_fuzzed_wav_files(blob, session_files, model_file, tmp_path, capsys):
    _run_compare(blob, session_files, model_file, tmp_path, capsys)


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(blob=wav_bytes())
def test_compare_on_fuzzed_wav_files_many(blob, session_files, model_file, tmp_path, capsys):
    _run_compare(blob, session_files, model_file, tmp_path, capsys)
