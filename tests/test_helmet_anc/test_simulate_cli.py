"""``helmet-anc simulate``: sample rate and sample format of the session written, and help with units."""

import json
import re

import pytest

from helmet_anc.cli import build_parser, main
from sysid.core.plants import appendix_a_model
from sysid.io.recordings import load_recording, open_recording
from sysid.io.wav import quantise

SHORT = ["--noise-seconds", "4", "--sweep-seconds", "0.5"]


@pytest.mark.parametrize("bits, code, width", [("16", 1, 2), ("24", 1, 3), ("32", 1, 4), ("float", 3, 4)])
def test_each_sample_format_is_written_and_reads_back_as_simulated(bits, code, width, tmp_path, capsys):
    assert main(["simulate", str(tmp_path / "s"), "--path", "ff", *SHORT, "--bits", bits]) == 0
    noise = tmp_path / "s" / "noise.wav"
    layout = open_recording(noise).layout
    raw = noise.read_bytes()
    assert int.from_bytes(raw[20:22], "little") == code and layout.sample_bytes == width
    recording = load_recording(noise)
    assert (recording.u == quantise(recording.u, bits)).all()  # samples on the format's grid
    assert json.loads((tmp_path / "s" / "truth.json").read_text())["spec"]["bits"] == bits


def test_another_sample_rate_resamples_the_plant(tmp_path, capsys):
    assert main(["simulate", str(tmp_path / "s"), "--path", "fb", *SHORT, "--fs", "48000",
                 "--effect", "delay:23"]) == 0
    truth = json.loads((tmp_path / "s" / "truth.json").read_text())
    assert open_recording(tmp_path / "s" / "noise.wav").fs == 48000.0 and truth["spec"]["fs"] == 48000.0
    assert truth["plant"]["fs"] == 48000.0
    # The same plant: its frequency response at 48 kHz is the 44.1 kHz one (zero-order hold, exact for a held input).
    from sysid.core.model import Model

    resampled = Model.from_dict(truth["base_plant"])
    original = appendix_a_model("fb")
    f = [50.0, 500.0, 2000.0]
    ratio = abs(resampled.frequency_response(f)) / abs(original.frequency_response(f))
    assert ratio == pytest.approx(1.0, abs=0.01)


def test_random_plant_at_another_rate_keeps_its_generator(tmp_path, capsys):
    assert main(["simulate", str(tmp_path / "s"), "--plant", "random", "--seed", "3", *SHORT, "--fs", "32000"]) == 0
    truth = json.loads((tmp_path / "s" / "truth.json").read_text())
    assert truth["spec"]["fs"] == 32000.0 and truth["generator"]["seed"] == 3


@pytest.mark.parametrize("argv, message", [(["--fs", "8000"], "--fs must be between 16000 and 192000 Hz"),
                                           (["--bits", "12"], "argument --bits: invalid choice: '12'")])
def test_a_rate_or_format_it_cannot_write_is_one_line(argv, message, tmp_path, capsys):
    try:
        code = main(["simulate", str(tmp_path / "s"), *SHORT, *argv])
    except SystemExit as exc:  # argparse's own refusals
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "s").exists()


def test_every_option_has_help_and_every_quantity_its_unit():
    parser = build_parser()
    simulate = parser._subparsers._group_actions[0].choices["simulate"]
    units = {"--noise-seconds": " s ", "--sweep-seconds": " s ", "--output-noise": "FS", "--input-noise": "FS",
             "--fs": "Hz", "--bits": "bit", "--seed": "whole number"}
    for action in simulate._actions:
        if action.dest == "help":
            continue
        assert action.help, action.option_strings or action.dest
        for option, unit in units.items():
            if option in action.option_strings:
                assert unit in action.help, (option, action.help)
    effect = next(a for a in simulate._actions if "--effect" in a.option_strings)
    assert re.search(r"resonance:f0_hz,q,gain_db", effect.help)
