"""Rendering: no model text can inject C, include guards are unique per output (names: test_c_syntax.py)."""

import subprocess

import pytest
from conftest_codegen import appendix_a_model, have

from codegen.context import build_context
from codegen.plan import plan_firmware
from codegen.render import render_files

# A model file name crafted to end the comment, splice a line (backslash-newline and the
# trigraph ??/ for a backslash) and declare a symbol.
HOSTILE = "m.json \\\nint injected_a = 1; /* ??/\nint injected_b = 2; */ int injected_c = 3; /*"


def _files(name="fb", provenance_extra=None):
    plan = plan_firmware(appendix_a_model("fb"))
    provenance = {**plan.provenance, **(provenance_extra or {})}
    context = build_context(name=name, provenance=provenance, fs=plan.realisation.fs, cascade=plan.cascade,
                            variants=tuple(plan.predictions), fixed=plan.fixed, floating=plan.floating)
    return render_files(context)


def test_hostile_model_text_injects_nothing(tmp_path):
    files = _files(provenance_extra={"file": HOSTILE, "hash": HOSTILE, "path": "fb*/ int injected_d;"})
    for text in files.values():
        assert "\\" not in text and "??" not in text and "injected_a = 1;" not in text
    if not have("gcc"):
        pytest.skip("gcc not installed: the compiled symbols are not checked")
    for filename, text in files.items():
        (tmp_path / filename).write_text(text)
    subprocess.run(["gcc", "-std=c99", "-trigraphs", "-Wall", "-Werror", "-c", "-o", "fb.o", "fb_filter.c"],
                   cwd=tmp_path, check=True, timeout=120)
    symbols = subprocess.run(["nm", "fb.o"], cwd=tmp_path, capture_output=True, text=True, check=True).stdout
    assert "injected" not in symbols


def test_include_guards_differ_per_name_and_headers_combine(tmp_path):
    headers = {}
    for name in ("ff", "ff_left"):
        headers.update({k: v for k, v in _files(name).items() if k.endswith(".h")})
    guards = {next(line.split()[1] for line in text.splitlines() if line.startswith("#ifndef")) for text in headers.values()}
    assert len(guards) == 2
    if not have("gcc"):
        pytest.skip("gcc not installed: the combined include is not compiled")
    for filename, text in headers.items():
        (tmp_path / filename).write_text(text)
    (tmp_path / "both.c").write_text('#include "ff_filter.h"\n#include "ff_left_filter.h"\n'
                                     "int both(void) { return FF_SECTIONS + FF_LEFT_SECTIONS; }\n")
    subprocess.run(["gcc", "-std=c99", "-Wall", "-Wpedantic", "-Werror", "-c", "both.c"], cwd=tmp_path, check=True,
                   timeout=60)
