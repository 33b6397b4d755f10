"""sysid.io.channels: swapped input and ear channels, told by the direction of the path's group delay.

The property on simulated sessions (appendix-A plants and random helmet paths): every
recording in the right channel order reads clear (the ear lags), the same recording with
its channels exchanged reads swapped; no false alarm. Plus the loader's ear checks
(silent, unrelated ear channel) accept the same sessions.
"""

import warnings

import numpy as np
import pytest

from helmet_anc.cli import main
from sysid.core.errors import RecordingError
from sysid.core.plants import appendix_a_model
from sysid.io.channels import LEAD_SAMPLES, ChannelOrderWarning, channel_order, check_channel_order
from sysid.io.recordings import load_recording, write_wav16
from sysid.random_plant import random_session
from sysid.simulate import SessionSpec, simulate_session, write_session

SHORT = dict(noise_duration=4.0, sweep_duration=1.0)


def _session(plant: str, path: str, seed: int):
    if plant == "random":
        return random_session(seed, path, **SHORT)
    return simulate_session(SessionSpec(path=path, seed=seed, **SHORT))


def _recordings(session):
    return {"noise": session.noise, "sweep1": session.sweeps[0], "sweep2": session.sweeps[1]}


# Random FB seed 18 has the smallest group delay measured (1.7 samples).
DEFAULT_CASES = [("appendix-a", "fb", 0), ("appendix-a", "ff", 0), ("random", "fb", 18), ("random", "ff", 3)]


@pytest.fixture(scope="module", params=DEFAULT_CASES, ids=lambda c: f"{c[0]}-{c[1]}-{c[2]}")
def written_session(request, tmp_path_factory):
    plant, path, seed = request.param
    session = _session(plant, path, seed)
    return session, write_session(session, tmp_path_factory.mktemp(f"{plant}_{path}_{seed}"))


def _assert_order_told(session):
    for name, recording in _recordings(session).items():
        right = channel_order(recording.u, recording.y, recording.fs)
        swapped = channel_order(recording.y, recording.u, recording.fs)
        assert right.clear and not right.swapped, (name, right)
        assert swapped.swapped and not swapped.clear, (name, swapped)
        assert right.group_delay == pytest.approx(-swapped.group_delay, abs=1e-6)


def test_right_order_is_clear_and_the_swapped_order_is_refused(written_session):
    _assert_order_told(written_session[0])


def test_the_loaders_ear_checks_accept_the_same_sessions(written_session):
    _, files = written_session
    with warnings.catch_warnings():
        warnings.simplefilter("error", ChannelOrderWarning)
        for key in ("noise", "sweep1", "sweep2"):
            recording = load_recording(files[key])
            check_channel_order(recording.u, recording.y, recording.fs, str(files[key]))


@pytest.mark.slow
@pytest.mark.parametrize("path", ["fb", "ff"])
@pytest.mark.parametrize("plant", ["appendix-a", "random"])
@pytest.mark.parametrize("seed", [0, 3])
def test_the_loaders_ear_checks_and_the_order_on_more_sessions(plant, path, seed, tmp_path):
    session = _session(plant, path, seed)
    files = write_session(session, tmp_path)
    for key in ("noise", "sweep1", "sweep2"):
        assert load_recording(files[key]).y.size > 0
    _assert_order_told(session)


@pytest.mark.slow
@pytest.mark.parametrize("path", ["fb", "ff"])
def test_no_false_alarm_on_many_random_helmets(path):
    """Seeds 0-40: every session with enough coherent bands to judge (seed 30 FB has not) reads right."""
    for seed in range(41):
        session = _session("random", path, seed)
        if all(channel_order(r.u, r.y, r.fs).judged for r in _recordings(session).values()):
            _assert_order_told(session)


def test_a_pure_delay_is_told_by_its_sign():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(44100)
    y = np.concatenate((np.zeros(5), 0.5 * u[:-5])) + 1e-3 * rng.standard_normal(u.size)
    assert channel_order(u, y, 44100.0).group_delay == pytest.approx(5.0, abs=0.05)
    assert channel_order(y, u, 44100.0).group_delay == pytest.approx(-5.0, abs=0.05)


def test_a_pure_gain_is_unclear_a_warning_not_an_error():
    rng = np.random.default_rng(1)
    u = rng.standard_normal(44100)
    y = 0.5 * u + 1e-3 * rng.standard_normal(u.size)
    order = channel_order(u, y, 44100.0)
    assert order.judged and abs(order.group_delay) < LEAD_SAMPLES
    with pytest.warns(ChannelOrderWarning, match=r"gain.wav: .*does not clearly lag.*--input-channel/--output-channel"):
        check_channel_order(u, y, 44100.0, "gain.wav")


def test_swapped_channels_error_names_the_file_and_the_fix():
    rng = np.random.default_rng(2)
    u = rng.standard_normal(44100)
    y = np.concatenate((np.zeros(20), u[:-20]))
    with pytest.raises(RecordingError, match=r"^s.wav: channel 1 \(taken as the ear\) leads channel 0 \(taken as "
                                             r"the input\) by 20 samples.*--input-channel 1 --output-channel 0$"):
        check_channel_order(y, u, 44100.0, "s.wav")


def test_too_short_or_incoherent_is_not_judged():
    rng = np.random.default_rng(3)
    assert not channel_order(rng.standard_normal(1000), rng.standard_normal(1000), 44100.0).judged
    assert not channel_order(rng.standard_normal(44100), rng.standard_normal(44100), 44100.0).judged


def test_compare_runs_on_swapped_files_given_the_channel_options(sessions, tmp_path, capsys):
    """The fix the message names works: the same sweeps written swapped, read with the options swapped."""
    model = tmp_path / "ff.json"
    appendix_a_model("ff").save(model)
    files = []
    for k, sweep in enumerate(sessions["ff"].sweeps):
        files.append(tmp_path / f"swapped{k}.wav")
        write_wav16(files[-1], sweep.y, sweep.u, sweep.fs)
    argv = ["compare", str(model), "--sweep", str(files[0]), "--sweep", str(files[1])]
    assert main(argv) == 2
    assert "--input-channel 1 --output-channel 0" in capsys.readouterr().err
    assert main(argv + ["--input-channel", "1", "--output-channel", "0"]) == 0
