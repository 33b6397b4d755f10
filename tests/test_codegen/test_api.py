"""Tests of codegen.api (generate_firmware, verification table) and codegen.verify."""

import json
import re

import numpy as np
import pytest
from conftest_codegen import appendix_a_model, model_sweeps

from codegen import __version__
from codegen.api import format_verification_table, generate_firmware
from codegen.build import build_host
from codegen.c_syntax import float_literal
from codegen.errors import VerificationError
from codegen.plan import plan_firmware
from codegen.verify import verify_host


@pytest.fixture(scope="module")
def fb_manifest(tmp_path_factory):
    model = appendix_a_model("fb")
    out = tmp_path_factory.mktemp("api") / "fb"
    return generate_firmware(model, out, sweeps=model_sweeps(model, seconds=0.2))


class TestGenerateFirmware:
    def test_manifest_contents(self, fb_manifest):
        data = json.loads((fb_manifest.outdir / "manifest.json").read_text())
        assert data == fb_manifest.data
        assert data["generator"] == f"helmet-anc codegen {__version__}"
        assert len(data["realisation"]["hankel_singular_values"]) == 7
        assert [s["order"] for s in data["cascade"]["sections"]] == [2, 2, 2, 1]
        assert set(data["formats"]) == {"q15", "float"} and set(data["predicted"]) == {"q15", "float"}
        for row in data["verification"]["sweeps"]:
            assert row["q15"]["max_lsb_difference"] == 0
            assert row["float"]["bit_exact"]
            assert row["q15"]["snr_vs_float64_db"] > 80 and row["float"]["snr_vs_float64_db"] > 75

    def test_file_hashes_and_literals(self, fb_manifest):
        source = (fb_manifest.outdir / "fb_filter.c").read_text()
        import hashlib

        assert fb_manifest.data["files"]["fb_filter.c"] == hashlib.sha256(source.encode()).hexdigest()
        for section in fb_manifest.data["formats"]["q15"]["sections"]:
            for value in section["b"] + section["a"]:
                if value:
                    assert f"INT32_C({value})" in source
        for section in fb_manifest.data["formats"]["float"]["sections"]:
            for value in section["c"]:
                if value:
                    literal = float_literal(value)
                    assert literal in source and np.float32(float(literal[:-1])) == np.float32(value)

    def test_verification_table(self, fb_manifest):
        table = format_verification_table(fb_manifest)
        lines = table.splitlines()
        assert lines[0].startswith("fb (FB, generic, 44100 Hz)")
        assert len([line for line in lines if " q15 " in line]) == 2
        assert all("0 LSB" in line for line in lines if " q15 " in line)
        assert re.search(r"float .* bit-exact", table)

    def test_board_rate_and_delay(self, tmp_path):
        model = appendix_a_model("ff")
        model.delay = 10
        manifest = generate_firmware(model, tmp_path / "ff48", fs=48000.0, sweeps=[model_sweeps(model, 0.1)[0]])
        board = manifest.data["board"]
        assert board["fs"] == 48000.0 and board["delay"] == 11 and board["resampled_from"] == 44100.0
        assert "#define FF_DELAY 11" in (tmp_path / "ff48" / "ff_filter.h").read_text()
        assert manifest.verification["sweeps"][0]["q15"]["max_lsb_difference"] == 0


def test_verification_detects_a_changed_coefficient(tmp_path):
    model = appendix_a_model("ff")
    manifest = generate_firmware(model, tmp_path / "ff")
    header = (tmp_path / "ff" / "ff_filter.h").read_text()
    source = (tmp_path / "ff" / "ff_filter.c").read_text()
    value = manifest.data["formats"]["q15"]["sections"][1]["b"][0]
    tampered = source.replace(f"INT32_C({value})", f"INT32_C({value + 1})", 1)
    assert tampered != source
    host = build_host("ff", header, tampered)
    with pytest.raises(VerificationError, match="differs from the bit-exact reference"):
        verify_host(plan_firmware(model), host, model_sweeps(model, seconds=0.3))


def test_unverified_table_shows_predictions(tmp_path):
    manifest = generate_firmware(appendix_a_model("ff"), tmp_path / "ff", variant="float")
    table = format_verification_table(manifest.data)
    assert "(not verified)" in table and "float" in table


def test_sweeps_as_recordings(tmp_path):
    from sysid.io.recordings import recording_from_arrays

    model = appendix_a_model("ff")
    sweep = model_sweeps(model, seconds=0.1)[0]
    recording = recording_from_arrays(sweep, model.simulate(sweep), model.fs, name="chin_sweep.wav")
    manifest = generate_firmware(model, tmp_path / "ff", variant="q15", sweeps=[recording])
    row = manifest.verification["sweeps"][0]
    assert row["sweep"] == "chin_sweep.wav" and row["q15"]["max_lsb_difference"] == 0
