"""The package facade ``sysid``: its public names, read lazily, and what a module of it loads."""

import json
import os
import subprocess
import sys

import pytest

import sysid
from repo import REPO


def _modules_after(statement: str) -> list[str]:
    """The ``sysid`` modules loaded in a fresh interpreter after ``statement`` (this source tree first)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    child = (f"import json, sys\n{statement}\n"
             "print(json.dumps(sorted(m for m in sys.modules if m == 'sysid' or m.startswith('sysid.'))))")
    done = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, env=env, timeout=300,
                          check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


# What a synthetic session needs: the core, the recordings and the registry of effects, not the estimators.
ESTIMATION_STACK = ("sysid.refits", "sysid.findings", "sysid.identify", "sysid.estimation", "sysid.diagnose",
                    "sysid.refine", "sysid.validation")


def _loaded(modules: list[str], packages) -> list[str]:
    return [m for m in modules if any(m == p or m.startswith(p + ".") for p in packages)]


def test_simulate_loads_no_estimation():
    modules = _modules_after("import sysid.simulate")
    assert _loaded(modules, ESTIMATION_STACK) == []
    assert {"sysid.simulate", "sysid.effects", "sysid.effects.delay", "sysid.io.recordings",
            "sysid.core.model"} <= set(modules)


def test_the_registry_resolves_a_builder_when_it_is_read():
    _modules_after("import sysid.simulate\n"
                   "from sysid import effects\n"
                   "delay = effects.get('delay')\n"
                   "assert 'sysid.refits' not in sys.modules\n"
                   "build = delay.build\n"
                   "from sysid.refits import add_delay\n"
                   "assert build is add_delay, build")


def test_the_core_loads_alone():
    assert _loaded(_modules_after("import sysid.core.model"), ESTIMATION_STACK + ("sysid.effects", "sysid.io")) == []


def test_importing_sysid_installs_the_old_paths_finder():
    modules = _modules_after("import sysid\n"
                             "assert any(type(f).__name__ == '_MovedFinder' for f in sys.meta_path)")
    assert modules == ["sysid", "sysid._moved"]


def test_the_public_names_are_those_of_their_modules():
    from sysid.diagnose import diagnose
    from sysid.identify import identify
    from sysid.refine import refine
    from sysid.simulate import simulate_session
    assert len(sysid.__all__) == len(set(sysid.__all__)) == 43
    assert set(sysid.__all__) <= set(dir(sysid))
    for name in sysid.__all__:
        assert getattr(sysid, name) is not None
    # A function keeps its name when its module of the same name is imported.
    assert sysid.diagnose is diagnose and sysid.identify is identify and sysid.refine is refine
    assert sysid.simulate_session is simulate_session
    namespace = {}
    exec("from sysid import *", namespace)
    assert set(namespace) - {"__builtins__"} == set(sysid.__all__)


def test_the_subpackages_read_as_attributes():
    for name in ("core", "effects", "estimation", "findings", "io", "refits", "simulate", "validation"):
        assert getattr(sysid, name).__name__ == f"sysid.{name}"
    assert sysid.report.__name__ == "report"
    with pytest.raises(AttributeError, match="has no attribute 'wobble'"):
        sysid.wobble
