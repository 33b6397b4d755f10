"""``--report``/``report -o`` naming a folder: written into it when it exists, refused when it does not, never a
file of the folder's name."""

import pytest

from helmet_anc.cli import main
from report.target import report_file
from sysid.core.errors import HelmetAncError
from sysid.core.plants import appendix_a_model


def _recordings(files):
    return ["--noise", str(files["noise"]), "--sweep", str(files["sweep1"]), "--sweep", str(files["sweep2"])]


@pytest.mark.parametrize("command", ["identify", "refine", "report"])
def test_a_folder_that_does_not_exist_is_refused_before_any_work(command, session_files, tmp_path, capsys):
    appendix_a_model("ff").save(tmp_path / "model.json")
    argv = {"identify": ["identify", *_recordings(session_files), "--path", "ff", "-o", str(tmp_path / "m.json"),
                         "--report", str(tmp_path / "reps") + "/"],
            "refine": ["refine", str(tmp_path / "model.json"), *_recordings(session_files), "--add", "delay:2",
                       "-o", str(tmp_path / "r.json"), "--report", str(tmp_path / "reps") + "/"],
            "report": ["report", str(tmp_path / "model.json"), *_recordings(session_files),
                       "-o", str(tmp_path / "reps") + "/"]}[command]
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"reps/: folder {tmp_path / 'reps'} does not exist; create it first" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no file named reps


def test_the_rule_names_the_file_in_a_folder(tmp_path):
    (tmp_path / "reps").mkdir()
    assert report_file(tmp_path / "reps", "ff") == tmp_path / "reps" / "ff-report.html"
    assert report_file(str(tmp_path / "reps") + "/", "fb") == tmp_path / "reps" / "fb-report.html"
    assert report_file(tmp_path / "r.html", "fb") == tmp_path / "r.html"
    assert report_file(tmp_path / "new", "fb") == tmp_path / "new"  # no separator: a file name
    with pytest.raises(HelmetAncError, match="does not exist"):
        report_file(str(tmp_path / "missing") + "/", "fb")


def test_an_existing_report_in_the_folder_that_is_not_ours_is_not_replaced(session_files, tmp_path, capsys):
    (tmp_path / "reps").mkdir()
    (tmp_path / "reps" / "ff-report.html").write_text("<p>my notes</p>")
    appendix_a_model("ff").save(tmp_path / "model.json")
    assert main(["report", str(tmp_path / "model.json"), *_recordings(session_files), "-o", str(tmp_path / "reps")]) == 2
    assert "was not written by helmet-anc" in capsys.readouterr().err
    assert (tmp_path / "reps" / "ff-report.html").read_text() == "<p>my notes</p>"
