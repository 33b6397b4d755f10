"""Reading the sessions of a batch: session folders and CSV manifests."""

from __future__ import annotations

from pathlib import Path

import pytest

from batch.manifest import SESSION_FILES, Skipped, find_sessions, read_sessions
from sysid.core.errors import HelmetAncError


def _session(folder: Path) -> Path:
    folder.mkdir(parents=True)
    for name in SESSION_FILES:
        (folder / name).write_bytes(b"")
    return folder


class TestFolder:
    def test_parts_name_helmet_head_condition_path(self, tmp_path):
        _session(tmp_path / "H1" / "rider03" / "loose" / "ff")
        _session(tmp_path / "H1" / "rider04")
        entries = read_sessions(tmp_path)
        assert [(e.helmet, e.head, e.condition, e.path) for e in entries] == [
            ("H1", "rider03", "loose", "ff"), ("H1", "rider04", "", "fb")]
        assert entries[0].name == "H1_rider03_loose_ff"
        assert entries[0].noise == str((tmp_path / "H1" / "rider03" / "loose" / "ff" / "noise.wav").resolve())

    def test_an_incomplete_session_folder_is_skipped_and_named_with_what_it_lacks(self, tmp_path):
        _session(tmp_path / "H1" / "r0")
        (_session(tmp_path / "H1" / "r1") / "sweep2.wav").unlink()
        (_session(tmp_path / "H1" / "r2") / "noise.wav").unlink()  # found by its sweeps alone
        entries, skipped = find_sessions(tmp_path)
        assert [e.head for e in entries] == ["r0"]
        assert skipped == [Skipped("H1/r1", "lacks sweep2.wav"), Skipped("H1/r2", "lacks noise.wav")]

    def test_only_incomplete_folders_say_which(self, tmp_path):
        (_session(tmp_path / "H1" / "r1") / "noise.wav").unlink()
        with pytest.raises(HelmetAncError, match=r"no sessions found .*; skipped 1 folder\(s\): H1/r1 lacks noise.wav"):
            read_sessions(tmp_path)

    def test_empty_folder(self, tmp_path):
        with pytest.raises(HelmetAncError, match="no sessions found"):
            read_sessions(tmp_path)


class TestManifest:
    def test_relative_paths_resolve_against_the_manifest(self, tmp_path):
        data = _session(tmp_path / "data" / "a")
        manifest = tmp_path / "lists" / "m.csv"
        manifest.parent.mkdir()
        manifest.write_text("helmet,rider,condition,path,noise,sweep1,sweep2\n"
                            "H2,dummy,tight,ff,../data/a/noise.wav,../data/a/sweep1.wav,../data/a/sweep2.wav\n")
        (entry,) = read_sessions(manifest)
        assert (entry.helmet, entry.head, entry.condition, entry.path) == ("H2", "dummy", "tight", "ff")
        assert entry.sweep2 == str((data / "sweep2.wav").resolve())

    def test_missing_column(self, tmp_path):
        manifest = tmp_path / "m.csv"
        manifest.write_text("helmet,head,path,noise,sweep1,sweep2\nH,h,fb,n.wav,a.wav,b.wav\n")
        with pytest.raises(HelmetAncError, match=r"m.csv: manifest lacks column\(s\) condition"):
            read_sessions(manifest)

    def test_bad_path_names_the_line(self, tmp_path):
        manifest = tmp_path / "m.csv"
        manifest.write_text("helmet,head,condition,path,noise,sweep1,sweep2\nH,h,c,fx,n.wav,a.wav,b.wav\n")
        with pytest.raises(HelmetAncError, match=r"line 2: path must be fb or ff; found 'fx'"):
            read_sessions(manifest)

    def test_duplicate_sessions_refused(self, tmp_path):
        manifest = tmp_path / "m.csv"
        manifest.write_text("helmet,head,condition,path,noise,sweep1,sweep2\n"
                            "H,h,c,fb,n.wav,a.wav,b.wav\nH,h,c,fb,n2.wav,a2.wav,b2.wav\n")
        with pytest.raises(HelmetAncError, match="two sessions have the name 'H_h_c_fb'"):
            read_sessions(manifest)

    def test_missing_source(self, tmp_path):
        with pytest.raises(HelmetAncError, match="no such folder or manifest"):
            read_sessions(tmp_path / "nothing.csv")
