"""codegen flows one way: every module loads after only the modules below it, with no import inside a function.

``FLOORS`` lists the modules leaves first: the errors, C syntax and manifest, the design
modules, the host build, the target descriptions, then the steps plan -> context ->
render -> verify and ``api``, which joins them. A module may import only modules on
an earlier line; a fresh interpreter importing them in this order sees each import
load exactly that module, which proves that none needs a lazy import to load.
"""

import ast
import json
import os
import subprocess
import sys

import pytest
from repo import REPO

# Leaves first; a module imports only modules listed before it.
FLOORS = [
    "codegen",
    # Leaves.
    "codegen.errors",
    "codegen.c_syntax",
    "codegen.manifest",
    # The design of the numbers.
    "codegen.realise",
    "codegen.sections",
    "codegen.fixedpoint",
    "codegen.float32",
    "codegen.reference",
    "codegen.cmsis",
    "codegen.noise",
    "codegen.qemu_cost",
    "codegen.control_loop",
    # Running generated code on the host (a leaf of the steps).
    "codegen.build",
    # The kinds of generated code.
    "codegen.targets",
    # The steps.
    "codegen.plan",
    "codegen.controller",
    "codegen.context",
    "codegen.render",
    "codegen.verify",
    "codegen.api",
]
# Packages of the project (the rest is the standard library and third-party packages).
PROJECT = ("codegen", "anc", "sysid", "report", "batch", "helmet_anc")


def _module_path(module: str):
    parts = module.split(".")
    folder = REPO.joinpath(*parts)
    return folder / "__init__.py" if folder.is_dir() else REPO.joinpath(*parts[:-1], parts[-1] + ".py")


def _imports(module: str) -> list[tuple[str, bool]]:
    """(imported module, inside a function) for every import statement of ``module``."""
    tree = ast.parse(_module_path(module).read_text(encoding="utf-8"))
    package = module if _module_path(module).name == "__init__.py" else module.rpartition(".")[0]
    nested = {id(node) for fn in ast.walk(tree) if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef))
              for node in ast.walk(fn) if node is not fn}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(alias.name, id(node) in nested) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else []))
            # "from . import noise" imports the module codegen.noise, "from . import __version__" a name.
            for alias in node.names:
                candidate = f"{base}.{alias.name}"
                found.append((candidate if candidate in FLOORS else base, id(node) in nested))
    return found


def test_every_module_is_placed():
    modules = {"codegen"} | {f"codegen.{p.stem}" for p in (REPO / "codegen").glob("*.py") if p.stem != "__init__"}
    assert sorted(modules) == sorted(FLOORS)


@pytest.mark.parametrize("module", FLOORS)
def test_imports_only_modules_below_it(module):
    below = FLOORS[: FLOORS.index(module)]
    for imported, _ in _imports(module):
        if imported.startswith("codegen.") or imported == "codegen":
            assert imported in below or imported == "codegen", f"{module} imports {imported}, not below it"


@pytest.mark.parametrize("module", FLOORS)
def test_no_project_import_inside_a_function(module):
    lazy = [name for name, inside in _imports(module) if inside and name.split(".")[0] in PROJECT]
    assert lazy == [], f"{module} imports {lazy} inside a function"


def test_a_fresh_interpreter_loads_each_module_alone_in_this_order():
    script = (
        "import importlib, json, sys\n"
        f"order = {FLOORS!r}\n"
        "extra = {}\n"
        "for name in order:\n"
        "    before = {m for m in sys.modules if m == 'codegen' or m.startswith('codegen.')}\n"
        "    importlib.import_module(name)\n"
        "    loaded = {m for m in sys.modules if m == 'codegen' or m.startswith('codegen.')} - before - {name}\n"
        "    if loaded:\n"
        "        extra[name] = sorted(loaded)\n"
        "print(json.dumps(extra))\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, cwd=REPO,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout.strip().splitlines()[-1]) == {}


def test_anc_is_below_codegen():
    # codegen reads controllers from anc; anc never reads codegen.
    for path in (REPO / "anc").glob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        names = [alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names]
        names += [node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and not node.level]
        assert not [n for n in names if n.split(".")[0] == "codegen"], f"anc/{path.name} imports codegen"
