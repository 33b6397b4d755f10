"""The manifest beside generated code and the folder it vouches for (codegen.manifest)."""

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest

from codegen import __version__
from codegen.errors import OutputError
from codegen.manifest import (MANIFEST_FORMAT, Manifest, check_output, json_ready, manifest_data, manifest_text,
                              write_directory)

FILES = {"ff_filter.h": "/* header */\n", "ff_filter.c": "/* source */\n"}


def _write(outdir, files=FILES, force=False):
    text = manifest_text(json_ready(manifest_data("ff", files, None, variant="both")))
    return write_directory(outdir, {**files, "manifest.json": text}, force=force)


class TestJsonReady:
    def test_non_finite_floats_become_none(self):
        assert json_ready({"a": [1.5, math.inf, np.float64(np.nan)], "b": (np.float32(2.0), -np.inf)}) == \
            {"a": [1.5, None, None], "b": [2.0, None]}

    def test_numpy_integers_become_ints(self):
        value = json_ready([np.int64(3), np.int16(-2)])
        assert value == [3, -2] and all(type(v) is int for v in value)


class TestManifestData:
    def test_records_format_generator_entries_and_file_hashes(self):
        data = manifest_data("ff", FILES, {"passed": True}, variant="q15", target="generic")
        assert data["format"] == MANIFEST_FORMAT and data["generator"] == f"helmet-anc codegen {__version__}"
        assert (data["name"], data["variant"], data["target"], data["verification"]) == ("ff", "q15", "generic",
                                                                                         {"passed": True})
        assert data["files"] == {name: hashlib.sha256(text.encode()).hexdigest() for name, text in FILES.items()}

    def test_text_is_sorted_json_with_a_final_newline(self):
        text = manifest_text({"b": 1, "a": [2.5]})
        assert text == '{\n  "a": [\n    2.5\n  ],\n  "b": 1\n}\n'
        with pytest.raises(ValueError):
            manifest_text({"a": math.nan})

    def test_record_reads_the_data(self, tmp_path):
        manifest = Manifest(outdir=tmp_path, data=manifest_data("ff", FILES, None))
        assert manifest.name == "ff" and manifest.verification is None
        assert sorted(manifest.files) == sorted(tmp_path / name for name in FILES)


class TestOutputFolder:
    def test_a_new_folder_is_written_whole(self, tmp_path):
        outdir = _write(tmp_path / "fw")
        assert sorted(p.name for p in Path(outdir).iterdir()) == ["ff_filter.c", "ff_filter.h", "manifest.json"]
        assert json.loads((outdir / "manifest.json").read_text())["format"] == MANIFEST_FORMAT

    def test_our_previous_output_is_replaced_and_its_stale_files_removed(self, tmp_path):
        _write(tmp_path / "fw")
        check_output(tmp_path / "fw")
        _write(tmp_path / "fw", {"fb_filter.h": "/* h */\n", "fb_filter.c": "/* c */\n"})
        assert sorted(p.name for p in (tmp_path / "fw").iterdir()) == ["fb_filter.c", "fb_filter.h", "manifest.json"]

    def test_a_folder_with_other_files_is_refused_unless_forced(self, tmp_path):
        (tmp_path / "fw").mkdir()
        (tmp_path / "fw" / "notes.txt").write_text("mine")
        with pytest.raises(OutputError, match="did not write"):
            check_output(tmp_path / "fw")
        with pytest.raises(OutputError, match="did not write"):
            _write(tmp_path / "fw")
        _write(tmp_path / "fw", force=True)
        assert (tmp_path / "fw" / "notes.txt").read_text() == "mine"
