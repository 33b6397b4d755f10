"""Fuzzing effect strings (hypothesis): ``--effect``/``--add`` text is parsed or refused in one line.

Property: the parsers return a spec or raise HelmetAncError with a one-line message; the
command line (``simulate --effect``) exits 0 with a session or 2 with one line, writing nothing.
"""

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from helmet_anc.cli import main
from sysid.core.effect_spec import parse_effect
from sysid.core.errors import HelmetAncError
from sysid.refine import parse_refinement
from sysid.simulate import SIMULATED_EFFECTS

KINDS = sorted(SIMULATED_EFFECTS) + ["reverb", "", "DELAY", "delay "]
PARTS = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers(-10**20, 10**20).map(str),
                  st.text(alphabet=st.characters(codec="utf-8"), max_size=6),
                  st.sampled_from(["", "=", "x=1", "step=1", "nan", "inf", "-0", "1e999", ",,"]))
EFFECTS = st.one_of(
    st.builds(lambda k, ps, sep: k + (":" + sep.join(ps) if ps else ""), st.sampled_from(KINDS),
              st.lists(PARTS, max_size=4), st.sampled_from([",", ", ", ";"])),
    st.text(max_size=20))


@settings(max_examples=300, deadline=None)
@given(text=EFFECTS)
def test_effect_parsers_return_or_raise_one_line(text):
    for parse in (lambda t: parse_effect(t, SIMULATED_EFFECTS), parse_refinement):
        try:
            parse(text)
        except HelmetAncError as exc:
            assert "\n" not in str(exc)


def _run_simulate(text, folder, capsys):
    target = folder / "session"
    try:
        code = main(["simulate", str(target), "--noise-seconds", "4", "--sweep-seconds", "0.2", "--effect", text])
    except SystemExit as stop:  # argparse's own refusals (a text it reads as an option)
        code = stop.code
    _, err = capsys.readouterr()
    if code == 0:
        assert (target / "truth.json").is_file()
    else:
        assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
        assert not target.exists()


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=EFFECTS)
@example(text="-:")  # read by argparse as an option: "--effect: expected one argument", exit 2
def test_simulate_with_fuzzed_effects(text, tmp_path_factory, capsys):
    _run_simulate(text, tmp_path_factory.mktemp("fx"), capsys)


@pytest.mark.slow
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=EFFECTS)
def test_simulate_with_fuzzed_effects_many(text, tmp_path_factory, capsys):
    _run_simulate(text, tmp_path_factory.mktemp("fx"), capsys)
