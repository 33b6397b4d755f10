"""The distribution ships every package and the C templates (a plain ``pip install .`` works)."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

tomllib = pytest.importorskip("tomllib") if sys.version_info >= (3, 11) else pytest.importorskip("tomli")


def _config():
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


# The top-level import packages of the distribution (codegen.templates lives in templates/).
TOP_PACKAGES = ("helmet_anc", "sysid", "codegen", "anc", "batch", "report")


def _package_folders() -> set[str]:
    """Dotted names of every folder with an ``__init__.py`` under the top-level packages."""
    return {".".join(p.parent.relative_to(ROOT).parts) for top in TOP_PACKAGES
            for p in (ROOT / top).rglob("__init__.py") if "__pycache__" not in p.parts}


def test_every_package_folder_is_listed():
    listed = set(_config()["tool"]["setuptools"]["packages"])
    found = _package_folders()
    assert found <= listed, f"packages missing from pyproject.toml: {sorted(found - listed)}"


def test_every_top_level_package_is_scanned():
    # A new top-level package (as anc and batch were) must join TOP_PACKAGES, or the check above misses it.
    tops = {p.parent.name for p in ROOT.glob("*/__init__.py")} - {"tests", "templates"}
    assert tops <= set(TOP_PACKAGES), f"top-level packages not in TOP_PACKAGES: {sorted(tops - set(TOP_PACKAGES))}"


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
