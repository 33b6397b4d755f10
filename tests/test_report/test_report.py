"""The HTML report: one self-contained file with every figure, the CLI, and a real browser rendering."""

import base64
import re
import shutil
import subprocess

import numpy as np
import pytest
from conftest import short_spec

from helmet_anc.cli import main
from report import html as report_html
from report import write_report
from sysid.core.model import Model
from sysid.core.plants import appendix_a_model
from sysid.diagnose import diagnose
from sysid.simulate import simulate_session, write_session

# The figures every report has (seed figures, validation, refinement), in page order.
FIXED_FIGURES = ["averaged-spectra", "smoothed-estimates", "singular-values", "rms-grid", "model-bode", "pole-zero",
                 "impulse-response", "order-curve", "sweep-1", "sweep-2", "error-bands", "residual-correlation", "coherence",
                 "refinement"]
DPI = 40


def _image_ids(text):
    return re.findall(r'<img id="fig-([a-z0-9-]+)"', text)


def _expected_finding_plots(findings):
    significant = [f["effect"] for f in findings if f["significant"]]
    return significant[:6] if significant else [max(findings, key=lambda f: f["score"])["effect"]]


@pytest.fixture(scope="module")
def ff_report(sessions, identifications, tmp_path_factory):
    session, result = sessions["ff"], identifications["ff"]
    findings = diagnose(result.model, session.noise, session.sweeps)
    path = write_report(tmp_path_factory.mktemp("report") / "ff.html", result.model, session.noise, session.sweeps,
                        result, findings, dpi=DPI)
    return path, findings


@pytest.fixture(scope="module")
def delay_files(tmp_path_factory):
    """A session with a hidden 23-sample delay, and the true plant without it (refined once before) as a file."""
    folder = tmp_path_factory.mktemp("delay")
    files = write_session(simulate_session(short_spec("ff", seed=5), effects=["delay:23"]), folder)
    model = appendix_a_model("ff")
    model.history = [{"effect": "resonance", "params": {"f0_hz": 3400.0}, "rms_before": 4e-3, "rms_after": 3e-3}]
    model.save(folder / "lacking-delay.json")
    return dict(files, model=folder / "lacking-delay.json")


@pytest.fixture(scope="module")
def cli_report(delay_files):
    """The report command on the delay session: no identification run, grid skipped."""
    output = delay_files["model"].parent / "out" / "report.html"
    output.parent.mkdir()
    code = main([str(a) for a in _report_args(delay_files["model"], delay_files, output, "--grid", "skip", "--dpi", "30")])
    return code, output


class TestReportFile:
    def test_one_file_with_every_figure(self, ff_report):
        path, findings = ff_report
        text = path.read_text(encoding="utf-8")
        expected = FIXED_FIGURES[:-1] + [f"finding-{e}" for e in _expected_finding_plots(findings)] + ["refinement"]
        assert _image_ids(text) == expected
        assert text.count("<img") == len(expected)
        assert text.count("<figcaption>") == len(expected)
        assert [p.name for p in path.parent.iterdir()] == ["ff.html"]

    def test_self_contained(self, ff_report):
        text = ff_report[0].read_text(encoding="utf-8")
        assert "http://" not in text and "https://" not in text
        assert "<script" not in text and "<link" not in text and "@import" not in text and "url(" not in text
        assert all(link.startswith("#") for link in re.findall(r'href="([^"]*)"', text))
        sources = re.findall(r'src="([^"]*)"', text)
        assert sources and all(s.startswith("data:image/png;base64,") for s in sources)
        for source in sources:
            png = base64.b64decode(source.split(",", 1)[1], validate=True)
            assert png[:8] == b"\x89PNG\r\n\x1a\n"

    def test_tables(self, ff_report, identifications):
        text = ff_report[0].read_text(encoding="utf-8")
        model = identifications["ff"].model
        for heading in ("State-space matrices", "second-order sections", "Hankel singular values"):
            assert heading in text
        assert f"{model.spectral_radius:.6f}" in text
        # Every finding is listed, significant or not.
        findings_table = text[text.index('class="findings"'):]
        for finding in ff_report[1]:
            assert f"<td>{finding['effect']}</td>" in findings_table

    def test_without_identification_grid_skipped_with_a_reason(self, cli_report):
        code, output = cli_report
        assert code == 0
        text = output.read_text(encoding="utf-8")
        assert [p.name for p in output.parent.iterdir()] == ["report.html"]
        ids = _image_ids(text)
        assert "rms-grid" not in ids and "was not recomputed" in text
        assert ids[:3] == FIXED_FIGURES[:3] and "sweep-2" in ids
        # The hidden delay is found and its evidence drawn; the history gives a staircase and a table.
        assert "finding-delay" in ids
        assert ids[-1] == "refinement" and "rms before (FS)" in text

    def test_into_a_folder(self, sessions, identifications, tmp_path, monkeypatch):
        session, result = sessions["ff"], identifications["ff"]
        monkeypatch.setattr(report_html, "figure_png", lambda figure, dpi: b"png")
        written = write_report(tmp_path, result.model, session.noise, session.sweeps, result, findings=[])
        assert written == tmp_path / "ff-report.html" and written.exists()

    def test_failure_leaves_no_file(self, sessions, identifications, tmp_path, monkeypatch):
        session, result = sessions["ff"], identifications["ff"]
        target = tmp_path / "r.html"
        target.write_text("previous report")
        calls = []

        def failing(figure, dpi):
            calls.append(1)
            if len(calls) == 3:
                raise RuntimeError("disk full")
            return b"png"

        monkeypatch.setattr(report_html, "figure_png", failing)
        with pytest.raises(RuntimeError, match="disk full"):
            write_report(target, result.model, session.noise, session.sweeps, result, findings=[], dpi=DPI)
        assert target.read_text() == "previous report"
        assert [p.name for p in tmp_path.iterdir()] == ["r.html"]


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def model_file(identifications, tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "ff.json"
    identifications["ff"].model.save(path)
    return path


def _report_args(model, files, output, *extra):
    return ["report", model, "--noise", files["noise"], "--sweep", files["sweep1"], "--sweep", files["sweep2"],
            "-o", output, *extra]


class TestCommand:
    def test_writes_the_report(self, cli_report):
        code, output = cli_report
        assert code == 0 and "fig-model-bode" in output.read_text(encoding="utf-8")

    @pytest.mark.parametrize("case,pattern", [
        ("missing-model", "cannot read model"),
        ("bad-json", "not valid JSON"),
        ("mono-noise", "mono file"),
        ("one-sweep", "give --sweep exactly twice"),
        ("no-folder", "does not exist"),
        ("rate-mismatch", "differs from the model's"),
        ("bad-dpi", "--dpi must be between"),
    ])
    def test_bad_input_one_line_error_no_file(self, case, pattern, model_file, session_files, tmp_path, capsys):
        import scipy.io.wavfile

        files = dict(session_files)
        model = model_file
        output = tmp_path / "out" / "report.html"
        output.parent.mkdir()
        extra = []
        if case == "missing-model":
            model = tmp_path / "none.json"
        elif case == "bad-json":
            model = tmp_path / "bad.json"
            model.write_text("{not json")
        elif case == "mono-noise":
            files["noise"] = tmp_path / "mono.wav"
            scipy.io.wavfile.write(files["noise"], 44100, np.ones(1000, np.int16))
        elif case == "no-folder":
            output = tmp_path / "missing" / "report.html"
        elif case == "rate-mismatch":
            data = Model.load(model_file).to_dict()
            data["fs"] = 48000.0
            model = tmp_path / "m48.json"
            Model.from_dict(data).save(model)
        elif case == "bad-dpi":
            extra = ["--dpi", "5"]
        argv = _report_args(model, files, output, *extra)
        if case == "one-sweep":
            argv = argv[:argv.index("--sweep") + 2] + argv[argv.index("--sweep") + 4:]
        code, _, err = _run(capsys, *argv)
        assert code == 2
        assert err.count("\n") == 1 and "Traceback" not in err and pattern in err
        assert not output.exists()
        if output.parent.exists():
            assert list(output.parent.iterdir()) == []


_CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(_CHROMIUM is None, reason="no chromium browser installed (apt-get install chromium)")
def test_renders_offline_in_a_headless_browser(ff_report, tmp_path):
    from PIL import Image

    shot = tmp_path / "shot.png"
    command = [_CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
               "--disable-background-networking", "--disable-component-update", "--disable-sync",
               # Any host name fails to resolve: the page must not need the network.
               "--host-resolver-rules=MAP * ~NOTFOUND", f"--user-data-dir={tmp_path / 'profile'}",
               f"--screenshot={shot}", "--window-size=1280,2000", ff_report[0].as_uri()]
    subprocess.run(command, capture_output=True, timeout=120, check=False)
    assert shot.exists(), "the browser wrote no screenshot"
    image = np.asarray(Image.open(shot).convert("L"), dtype=float)
    assert image.shape == (2000, 1280)
    # A rendered page has text and figures: many dark pixels on a light background, not a blank page.
    assert image.mean() > 180 and np.mean(image < 100) > 0.005


def test_decay_caption_stops_at_the_numerical_floor():
    """A response that is zero to double precision reads 'more than 300 dB below', never '-6401 dB'."""
    from report.model_figures import decay_label, transient_decay_db
    from sysid.core.model import Model

    fast = Model(path="fb", fs=44100.0, A=[[0.5]], B=[[1.0]], C=[[1.0]], D=[[0.0]])
    decay = transient_decay_db(fast, 3.0)
    assert decay_label(decay) == "more than 300 dB below its peak"
    assert decay_label(-72.4) == "72 dB below its peak"
