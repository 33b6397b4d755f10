"""sysid.validation.sweeps.check_repeats: two sweeps that are not repeats of one excitation are refused, with the
level difference (dB) and the excitations' lengths (s), by identify, compare and diagnose (API and command line);
repeats shifted in time, or of a path that changed between them, are not."""

import pytest
from conftest import FAST_OPTIONS, short_spec

from helmet_anc.cli import main
from sysid.core.errors import IdentificationError
from sysid.core.plants import appendix_a_model
from sysid.diagnose import diagnose
from sysid.identify import identify
from sysid.io.recordings import Recording
from sysid.simulate import SessionSpec, simulate_session, write_session
from sysid.validation.compare import compare
from sysid.validation.sweeps import check_repeats, excitation_seconds, repeat_check

HALF_LEVEL = r"the sweeps do not repeat each other: the second input is -6\.0 dB from the first \(excitations of " \
             r"2\.00 s and 2\.00 s\), which puts \d+\.\dx the noise into their difference"
OTHER_LENGTH = r"the sweeps do not repeat each other: their inputs are not one excitation \(excitations of 2\.00 s " \
               r"and 2\.50 s, correlation -?0\.\d\d at their best alignment"


def half_level(sweep: Recording) -> Recording:
    """The same sweep played at half the level (-6.02 dB): the ear follows the input."""
    return Recording(0.5 * sweep.u, 0.5 * sweep.y, sweep.fs, "half.wav")


@pytest.fixture(scope="module")
def other_length():
    """A 2.5 s sweep of the same band, recorded on the same rig as the 2 s ones of ``sessions``."""
    return simulate_session(short_spec("ff", seed=11, sweep_duration=2.5)).sweeps[1]


def test_repeats_of_one_excitation_pass_and_report_their_figures(sessions):
    check = check_repeats(*sessions["ff"].sweeps)
    assert check.repeats and check.correlation > 0.99 and abs(check.level_db) < 0.01
    assert check.lengths_s == pytest.approx((2.0, 2.0), abs=0.01)


def test_the_excitation_length_leaves_out_the_silence_around_a_sweep():
    for silence in (0.2, 1.0):
        sweep = simulate_session(SessionSpec(path="fb", noise_duration=4.0, sweep_duration=1.5,
                                             sweep_silence=silence)).sweeps[0]
        assert excitation_seconds(sweep) == pytest.approx(1.5, abs=0.01)


def test_a_sweep_at_half_level_is_refused_with_its_level_and_lengths(sessions):
    first, second = sessions["ff"].sweeps
    with pytest.raises(IdentificationError, match=HALF_LEVEL):
        check_repeats(first, half_level(second))


def test_a_sweep_of_another_length_is_refused_with_both_lengths(sessions, other_length):
    with pytest.raises(IdentificationError, match=OTHER_LENGTH):
        check_repeats(sessions["ff"].sweeps[0], other_length)


def test_identify_compare_and_diagnose_refuse_non_repeats(sessions):
    session = sessions["ff"]
    sweeps = [session.sweeps[0], half_level(session.sweeps[1])]
    with pytest.raises(IdentificationError, match=HALF_LEVEL):
        identify(session.noise, sweeps, "ff", FAST_OPTIONS)
    with pytest.raises(IdentificationError, match=HALF_LEVEL):
        compare(appendix_a_model("ff"), sweeps)
    with pytest.raises(IdentificationError, match=HALF_LEVEL):
        diagnose(appendix_a_model("ff"), session.noise, sweeps)


@pytest.mark.parametrize("effect", ["time-variation", "input-noise", "periodic-disturbance"])
def test_a_path_that_changes_or_a_noisy_input_is_still_a_repeat(effect):
    """The check reads the inputs: a path that changed between the repeats is diagnose's to name."""
    session = simulate_session(short_spec("ff", seed=2), effects=[effect])
    assert repeat_check(*session.sweeps).repeats


def test_a_shifted_repeat_is_aligned_not_refused(sessions):
    later = simulate_session(short_spec("ff", seed=11, sweep_silence=0.7)).sweeps[1]
    check = check_repeats(sessions["ff"].sweeps[0], later)
    assert check.correlation > 0.99 and abs(check.level_db) < 0.01


@pytest.mark.parametrize("command", ["identify", "compare", "diagnose"])
def test_the_command_line_refuses_non_repeats_in_one_line(command, sessions, tmp_path, capsys):
    files = write_session(sessions["ff"], tmp_path / "s")
    write_session(simulate_session(short_spec("ff", seed=11, sweep_duration=2.5)), tmp_path / "long")
    appendix_a_model("ff").save(tmp_path / "model.json")
    sweeps = ["--sweep", str(files["sweep1"]), "--sweep", str(tmp_path / "long" / "sweep2.wav")]
    argv = {"identify": ["identify", "--noise", str(files["noise"]), *sweeps, "--path", "ff", "-o",
                         str(tmp_path / "m.json")],
            "compare": ["compare", str(tmp_path / "model.json"), *sweeps],
            "diagnose": ["diagnose", str(tmp_path / "model.json"), "--noise", str(files["noise"]), *sweeps]}[command]
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and "excitations of 2.00 s and 2.50 s" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before
