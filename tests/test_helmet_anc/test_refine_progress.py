"""``helmet-anc refine --auto`` into a pipe: one progress line per step on stderr, the results on stdout."""

from conftest import short_spec

from helmet_anc.cli import main
from sysid.core.plants import appendix_a_model
from sysid.simulate import simulate_session, write_session


def test_refine_auto_says_each_step_when_stderr_is_a_pipe(tmp_path, capsys):
    files = write_session(simulate_session(short_spec("ff", seed=4), effects=["delay:23"]), tmp_path / "late")
    appendix_a_model("ff").save(tmp_path / "model.json")
    code = main(["refine", str(tmp_path / "model.json"), "--auto", "--noise", str(files["noise"]), "--sweep",
                 str(files["sweep1"]), "--sweep", str(files["sweep2"]), "-o", str(tmp_path / "refined.json")])
    out, err = capsys.readouterr()
    assert code == 0, err
    lines = err.splitlines()
    assert lines[0].startswith("refine --auto: step 1: diagnose (") and "x the noise floor)" in lines[0]
    assert "refine --auto: step 1: adding delay and refitting" in lines
    assert all(line.startswith("refine --auto: step ") for line in lines), err
    assert "\r" not in err and "1. + delay" in out
