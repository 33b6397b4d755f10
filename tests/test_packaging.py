"""The distribution ships every package and the C templates (a plain ``pip install .`` works)."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

tomllib = pytest.importorskip("tomllib") if sys.version_info >= (3, 11) else pytest.importorskip("tomli")


def _config():
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_every_package_folder_is_listed():
    listed = set(_config()["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for top in ("helmet_anc", "sysid", "codegen")
             for p in (ROOT / top).rglob("__init__.py") if "__pycache__" not in p.parts}
    assert found <= listed, f"packages missing from pyproject.toml: {sorted(found - listed)}"


def test_templates_are_shipped_as_package_data():
    config = _config()["tool"]["setuptools"]
    assert config["package-dir"]["codegen.templates"] == "templates"
    assert "*.j2" in config["package-data"]["codegen.templates"]
    assert list((ROOT / "templates").glob("*.j2"))


def test_console_scripts():
    scripts = _config()["project"]["scripts"]
    assert scripts == {"helmet-anc": "helmet_anc.cli:main", "generate-firmware": "helmet_anc.firmware_cli:main"}


def test_templates_are_found_from_the_installed_package_or_the_checkout():
    from codegen.render import template_folder

    names = {p.name for p in template_folder().iterdir()}
    assert {"filter.c.j2", "filter.h.j2", "cmsis_filter.c.j2", "cmsis_filter.h.j2"} <= names
