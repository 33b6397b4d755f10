"""sysid.core.files: atomic writes, output checks and the manifest-proved output folder."""

import json
import os
import stat

import pytest

from sysid.core.files import (OutputRefused, atomic_write, atomic_write_text, check_output_directory, check_output_file,
                              is_ours, sha256_text, write_output_directory)
from sysid.core.model import Model

TAG = "helmet-anc/test-manifest@1"


def _manifest(files: dict[str, str]) -> str:
    return json.dumps({"format": TAG, "files": {k: sha256_text(v) for k, v in files.items()}})


def _output(files: dict[str, str]) -> dict[str, str]:
    return {**files, "manifest.json": _manifest(files)}


def test_atomic_write_keeps_the_old_file_and_leaves_no_temporary_on_failure(tmp_path):
    target = tmp_path / "a.json"
    target.write_text("old")

    def fail(tmp):
        tmp.write_text("half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write(target, fail)
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]


def test_atomic_write_gives_the_ordinary_mode_not_mkstemp_private(tmp_path):
    umask = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "a.txt", "x")
        Model(path="fb", fs=1000.0, A=[[0.5]], B=[[1.0]], C=[[1.0]], D=[[0.0]]).save_mat(tmp_path / "m.mat")
    finally:
        os.umask(umask)
    for name in ("a.txt", "m.mat"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o644, name
    assert is_ours(tmp_path / "m.mat")


def test_check_output_file_refuses_inputs_foreign_files_and_folders(tmp_path):
    mine = tmp_path / "model.json"
    mine.write_text(json.dumps({"format": "helmet-anc/model@1"}))
    user = tmp_path / "notes.json"
    user.write_text("{}")
    assert check_output_file(mine) == mine  # ours: may be replaced
    with pytest.raises(OutputRefused, match="is an input"):
        check_output_file(mine, inputs=[str(mine)], force=True)
    os.link(mine, tmp_path / "hardlink.json")
    with pytest.raises(OutputRefused, match="is an input"):
        check_output_file(tmp_path / "hardlink.json", inputs=[mine])
    with pytest.raises(OutputRefused, match="not written by helmet-anc"):
        check_output_file(user)
    assert check_output_file(user, force=True) == user
    with pytest.raises(OutputRefused, match="is a folder"):
        check_output_file(tmp_path)
    with pytest.raises(OutputRefused, match="does not exist"):
        check_output_file(tmp_path / "missing" / "x.json")


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_check_output_file_refuses_a_read_only_folder(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        with pytest.raises(OutputRefused, match="not writable"):
            check_output_file(folder / "x.json")
    finally:
        folder.chmod(0o755)


def test_new_output_folder_is_written_whole(tmp_path):
    out = write_output_directory(tmp_path / "out", _output({"a.c": "int a;"}), "manifest.json", TAG)
    assert sorted(p.name for p in out.iterdir()) == ["a.c", "manifest.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staging folder left


def test_previous_output_is_replaced_and_its_stale_files_removed(tmp_path):
    out = tmp_path / "out"
    write_output_directory(out, _output({"a.c": "1", "b.c": "2"}), "manifest.json", TAG)
    write_output_directory(out, _output({"a.c": "3"}), "manifest.json", TAG)
    assert sorted(p.name for p in out.iterdir()) == ["a.c", "manifest.json"]
    assert (out / "a.c").read_text() == "3"


@pytest.mark.parametrize("case", ["user file", "no manifest", "edited file", "foreign manifest"])
def test_a_folder_with_user_files_is_refused_and_untouched(tmp_path, case):
    out = tmp_path / "out"
    if case == "no manifest":
        out.mkdir()
        (out / "main.c").write_text("user")
    else:
        write_output_directory(out, _output({"a.c": "1"}), "manifest.json", TAG)
        if case == "user file":
            (out / "main.c").write_text("user")
        elif case == "edited file":
            (out / "a.c").write_text("edited by the user")
        else:
            (out / "manifest.json").write_text(json.dumps({"format": "other", "files": {"a.c": "x"}}))
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(OutputRefused, match="--force"):
        write_output_directory(out, _output({"a.c": "2"}), "manifest.json", TAG)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_force_removes_only_files_the_manifest_lists(tmp_path):
    out = tmp_path / "out"
    write_output_directory(out, _output({"a.c": "1", "b.c": "2"}), "manifest.json", TAG)
    (out / "main.c").write_text("user")
    write_output_directory(out, _output({"c.c": "3"}), "manifest.json", TAG, force=True)
    assert sorted(p.name for p in out.iterdir()) == ["c.c", "main.c", "manifest.json"]
    assert (out / "main.c").read_text() == "user"


def test_a_manifest_cannot_name_files_outside_its_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.c"
    victim.write_text("keep")
    (out / "manifest.json").write_text(json.dumps({"format": TAG, "files": {"../victim.c": sha256_text("keep")}}))
    with pytest.raises(OutputRefused):
        check_output_directory(out, "manifest.json", TAG)
    write_output_directory(out, _output({"a.c": "1"}), "manifest.json", TAG, force=True)
    assert victim.read_text() == "keep"


# -- output trees (the demo's OUTDIR) --------------------------------------------

from sysid.core.files import OutputRefused as _Refused  # noqa: E402
from sysid.core.files import staged_output_tree

_TAG = "helmet-anc/test-tree@1"


def _tree(folder, files):
    for name, text in files.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)


def _contents(folder):
    return {p.relative_to(folder).as_posix(): p.read_text() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_new_tree_appears_complete_with_its_manifest(tmp_path):
    out = tmp_path / "out"
    with staged_output_tree(out, "m.json", _TAG) as work:
        _tree(work, {"a.txt": "1", "sub/b.txt": "2"})
        assert not out.exists()
    assert _contents(out).keys() == {"a.txt", "sub/b.txt", "m.json"}
    assert sorted(json.loads((out / "m.json").read_text())["files"]) == ["a.txt", "sub/b.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_a_rerun_replaces_and_removes_only_listed_files(tmp_path):
    out = tmp_path / "out"
    with staged_output_tree(out, "m.json", _TAG) as work:
        _tree(work, {"a.txt": "1", "sub/old.txt": "2"})
    with staged_output_tree(out, "m.json", _TAG) as work:
        _tree(work, {"a.txt": "new", "sub/b.txt": "3"})
    assert _contents(out) == {"a.txt": "new", "sub/b.txt": "3", "m.json": (out / "m.json").read_text()}


def test_a_folder_with_a_file_not_ours_is_refused_and_left_alone_without_force(tmp_path):
    out = tmp_path / "out"
    with staged_output_tree(out, "m.json", _TAG) as work:
        _tree(work, {"a.txt": "1"})
    _tree(out, {"sub/notes.txt": "mine"})
    before = _contents(out)
    with pytest.raises(_Refused, match=r"holds files not in our manifest \(sub/notes.txt\).*--force"):
        staged_output_tree(out, "m.json", _TAG)
    (out / "a.txt").write_text("edited")  # edited since we wrote it: the user's now
    with pytest.raises(_Refused, match="a.txt"):
        staged_output_tree(out, "m.json", _TAG)
    assert _contents(out) == {**before, "a.txt": "edited"}


def test_with_force_files_not_ours_stay_and_are_never_replaced(tmp_path):
    out = tmp_path / "out"
    _tree(out, {"mine.txt": "mine", "sub/c.txt": "mine too"})
    with staged_output_tree(out, "m.json", _TAG, force=True) as work:
        _tree(work, {"a.txt": "1"})
    assert _contents(out)["mine.txt"] == "mine" and _contents(out)["a.txt"] == "1"
    before = _contents(out)
    with pytest.raises(_Refused, match=r"would replace files helmet-anc did not write \(sub/c.txt\)"):
        with staged_output_tree(out, "m.json", _TAG, force=True) as work:
            _tree(work, {"a.txt": "2", "sub/c.txt": "ours"})
    assert _contents(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staging folder left


def test_an_interrupted_tree_leaves_the_folder_as_it_was(tmp_path):
    out = tmp_path / "out"
    with staged_output_tree(out, "m.json", _TAG) as work:
        _tree(work, {"a.txt": "1"})
    before = _contents(out)
    with pytest.raises(KeyboardInterrupt):
        with staged_output_tree(out, "m.json", _TAG) as work:
            _tree(work, {"a.txt": "2"})
            raise KeyboardInterrupt
    assert _contents(out) == before and sorted(p.name for p in tmp_path.iterdir()) == ["out"]
