"""docs/make_figures.py: the README's figures are reproducible byte for byte."""

import hashlib
import importlib.util
from pathlib import Path

import pytest
from repo import REPO

from sysid.findings import PROVIDERS

DOCS = REPO / "docs"


@pytest.fixture(autouse=True)
def delay_scan_value(monkeypatch):
    """The delay scan's shared value ``"delay-scan"`` (best total delay, cost per total delay with NaN where
    not evaluated) that the delay figure draws, provided here as the delay detector's coarse scan where no
    provider is registered."""
    if "delay-scan" not in PROVIDERS:
        from sysid.findings.delay import scan_delay
        monkeypatch.setitem(PROVIDERS, "delay-scan", lambda ctx: scan_delay(ctx, coarse=True))


def _make_figures():
    spec = importlib.util.spec_from_file_location("make_figures", DOCS / "make_figures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.make_figures


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.slow
def test_make_figures_twice_gives_the_same_bytes(tmp_path):
    """Seeded sessions and identification, no matplotlib version in the PNG metadata: the same bytes every run."""
    make_figures = _make_figures()
    first, second = make_figures(tmp_path / "a"), make_figures(tmp_path / "b")
    assert [p.name for p in first] == ["ff-model-bode.png", "ff-error-bands.png", "ff-delay-evidence.png"]
    for a, b in zip(first, second):
        assert _digest(a) == _digest(b), a.name
        assert b"Matplotlib version" not in a.read_bytes()
