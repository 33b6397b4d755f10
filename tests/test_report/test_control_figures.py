"""The report's control section (helmet-anc report --controller): report takes the section from the caller."""

from __future__ import annotations

import re

import numpy as np
import pytest

from control_cases import predicted_small_controller
from helmet_anc.cli import main
from sysid.core.plants import appendix_a_model


@pytest.fixture(scope="module")
def files(identifications, session_files, tmp_path_factory):
    """The FF session's files, its identified FF model and a controller designed on the seed FB path and that model."""
    folder = tmp_path_factory.mktemp("control_report")
    model = folder / "ff.json"
    identifications["ff"].model.save(model)
    controller = folder / "controller.json"
    # A stored controller (a design takes minutes): small filters with the predictions anc.design.predict makes.
    predicted_small_controller(appendix_a_model("fb"), identifications["ff"].model).save(controller)
    return {**session_files, "model": model, "controller": controller}


def _args(files, output, *extra):
    return ["report", str(files["model"]), "--noise", str(files["noise"]), "--sweep", str(files["sweep1"]),
            "--sweep", str(files["sweep2"]), "--grid", "skip", "--dpi", "40", "-o", str(output), *extra]


def test_report_with_controller_has_the_control_section(files, tmp_path):
    output = tmp_path / "report.html"
    assert main(_args(files, output, "--controller", str(files["controller"]))) == 0
    html = output.read_text(encoding="utf-8")
    section = html[html.index('<section id="control">'):]
    assert '<a href="#control">6. Control</a>' in html
    for caption in ("Attenuation per third-octave band", "Sensitivity |1 + G Q|", "uncertainty discs"):
        assert caption in section
    # Predicted and achieved per band for ff, fb and both; achieved on the seed plants within 2 dB
    # of predicted from 50 Hz to 1 kHz (the FF model here is the identified one, close to the truth).
    header = re.search(r"<tr><th>band \(Hz\)</th>(.*?)</tr>", section).group(1)
    assert header.count("predicted") == 3 and header.count("achieved") == 3
    rows = re.findall(r"<tr><td>([\d.]+)</td>((?:<td>-?[\d.]+</td>){6})", section)
    assert len(rows) == 21
    values = np.array([[float(v) for v in re.findall(r"-?[\d.]+", cells)] for _, cells in rows])
    centres = np.array([float(c) for c, _ in rows])
    checked = (centres >= 50) & (centres <= 1000)
    assert np.max(np.abs(values[checked, :3] - values[checked, 3:])) <= 2.0


def test_report_without_controller_has_no_control_section(files, tmp_path):
    output = tmp_path / "report.html"
    assert main(_args(files, output)) == 0
    assert 'id="control"' not in output.read_text(encoding="utf-8")


def test_controller_at_another_rate_is_one_line_error(files, tmp_path, capsys):
    import json

    data = json.loads(files["controller"].read_text())
    data["fs"] = data["internal_model"]["fs"] = 16000.0
    other = tmp_path / "c16k.json"
    other.write_text(json.dumps(data))
    output = tmp_path / "report.html"
    assert main(_args(files, output, "--controller", str(other))) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--controller" in err and "16000 Hz" in err
    assert not output.exists()
