"""helmet_anc.effect_modules: a user's own effect loaded with --effect-module, or refused in one line."""

import json
import shutil
import sys

import pytest
from repo import REPO

from helmet_anc.cli import main
from sysid.effects import registry


@pytest.fixture
def folder(tmp_path):
    shutil.copyfile(REPO / "tests" / "notch_effect.py", tmp_path / "notch_effect.py")
    (tmp_path / "broken.py").write_text("effect = (\n")
    (tmp_path / "raises.py").write_text("import math\nraise RuntimeError('no liner data')\n")
    (tmp_path / "nothing.py").write_text("LEVEL = 1\n")
    yield tmp_path
    if "notch" in registry.names():
        registry.unregister("notch")
    sys.modules.pop("notch_effect", None)


def test_simulate_gets_the_users_effect(folder, capsys):
    assert "notch" not in registry.names()
    assert main(["simulate", str(folder / "s"), "--noise-seconds", "4", "--sweep-seconds", "0.5", "--effect-module",
                 str(folder / "notch_effect.py"), "--effect", "notch:1200,4"]) == 0
    effects = json.loads((folder / "s" / "truth.json").read_text())["effects"]
    assert [e["effect"] for e in effects] == ["notch"] and effects[0]["params"] == {"f0_hz": 1200.0, "q": 4.0}


@pytest.mark.parametrize("name, message", [
    ("missing.py", "--effect-module {folder}/missing.py: no such file"),
    ("broken.py", "--effect-module {folder}/broken.py: does not load (SyntaxError at line 1: '(' was never closed)"),
    ("raises.py", "--effect-module {folder}/raises.py: does not load (RuntimeError at line 2: no liner data)"),
    ("nothing.py", "--effect-module {folder}/nothing.py: registers no effect"),
])
def test_a_missing_or_broken_module_is_one_line(name, message, folder, capsys):
    before = registry.names()
    assert main(["simulate", str(folder / "s"), "--effect-module", str(folder / name), "--effect", "notch:1200"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message.format(folder=folder) in err, err
    assert not (folder / "s").exists() and registry.names() == before
