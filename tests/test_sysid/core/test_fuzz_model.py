"""Fuzzing model JSON (hypothesis): a model file is either used or refused in one line, never a traceback.

Property: ``helmet-anc compare MODEL --sweep S1 --sweep S2 --json OUT`` exits 0 with a valid
result, or exits 2 with exactly one line on stderr; no input file changes and nothing is
written on exit 2.
"""

import json
import math

import pytest
from bad_inputs import snapshot
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helmet_anc.cli import main
from sysid.core.errors import ModelError
from sysid.core.model import Model

NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30),
                    st.sampled_from([0.0, 0.5, -0.9, 1e300, 1e-300, 1e9]))
SCALARS = st.one_of(NUMBERS, st.text(max_size=5), st.booleans(), st.none())
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                        st.dictionaries(st.text(max_size=3), inner, max_size=3)),
                      max_leaves=12)


def _matrix(rows, cols):
    return st.lists(st.lists(NUMBERS, min_size=cols, max_size=cols), min_size=rows, max_size=rows)


@st.composite
def model_documents(draw):
    """A valid model of order 1-3, with some fields replaced by random JSON values or badly shaped matrices."""
    n = draw(st.integers(1, 3))
    document = {"format": "helmet-anc/model@1", "path": "ff", "fs": 44100.0,
                "A": [[0.5 if i == j else 0.0 for j in range(n)] for i in range(n)],
                "B": [[1.0]] * n, "C": [[0.1] * n], "D": [[0.0]], "delay": 0}
    for key in draw(st.lists(st.sampled_from(sorted(document) + ["input_nonlinearity", "disturbance"]),
                             max_size=3, unique=True)):
        document[key] = draw(st.one_of(VALUES, _matrix(draw(st.integers(0, 3)), draw(st.integers(0, 3))),
                                       st.floats(), st.integers(-10**12, 10**400)))
    return document


@settings(max_examples=60, deadline=None)
@given(document=model_documents())
def test_model_from_dict_accepts_or_raises_model_error(document):
    try:
        model = Model.from_dict(document)
    except ModelError as exc:
        assert "\n" not in str(exc)
        return
    assert model.stable in (True, False) and all(math.isfinite(v) for v in model.A.ravel())


def _run_compare(document, session_files, folder, capsys):
    model_file = folder / "fuzz_model.json"
    model_file.write_text(json.dumps(document))
    out_file = folder / "fuzz_out.json"
    out_file.unlink(missing_ok=True)
    before = snapshot(folder)
    code = main(["compare", str(model_file), "--sweep", str(session_files["sweep1"]), "--sweep",
                 str(session_files["sweep2"]), "--json", str(out_file)])
    out, err = capsys.readouterr()
    if code == 0:
        assert json.loads(out_file.read_text())["format"] == "helmet-anc/comparison@1"
    else:
        assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
        assert snapshot(folder) == before


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(document=model_documents())
def test_compare_on_fuzzed_model_files(document, session_files, tmp_path, capsys):
    _run_compare(document, session_files, tmp_path, capsys)


@pytest.mark.slow
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(document=model_documents())
def test_compare_on_fuzzed_model_files_many(document, session_files, tmp_path, capsys):
    _run_compare(document, session_files, tmp_path, capsys)
