"""The house's rules, read from the source: no import cycles, imports only downwards, small modules, old paths kept.

Static: every ``.py`` file of the project's packages is parsed with ``ast`` (never
imported), and every ``import`` statement counts, at module level or inside a function,
since a function-level import is a dependency too, only a later one. An import names
the module it loads: ``from a.b import c`` is ``a.b.c`` when that is a module, else
``a.b``; an old path of ``sysid._moved.MOVED`` is read as its new one. The rules:

(a) no import cycle among the project's modules;
(b) packages import only downwards: sysid <- anc <- codegen <- report <- batch <- helmet_anc
    (an arrow reads "is imported by"; helmet_anc, the front end, may import anything);
(c) inside sysid, the stages import only downwards, in the pipeline's order
    core < io < validation < estimation < identify < findings < refits < effects < the
    verbs (diagnose, refine, simulate, random_plant) and ``sysid/__init__``;
(d) no module of the project outside the tests has more than ``MAX_LINES`` lines;
(e) every old import path of ``sysid._moved.MOVED`` still imports, with a DeprecationWarning,
    and gives the same objects as the new path.

Each failure names the offending files and lines.
"""

import ast
import json
import os
import subprocess
import sys
from dataclasses import dataclass

import pytest
from repo import REPO

# The project's import packages (the tests and the C templates aside).
PACKAGES = ("sysid", "anc", "codegen", "report", "batch", "helmet_anc")
# Folders whose Python files are held to the size rule (d) besides the packages.
SIZED_FOLDERS = PACKAGES + ("benchmarks", "docs")
MAX_LINES = 500

# (b) The packages each package may import (itself always).
MAY_IMPORT = {
    "sysid": set(),
    "anc": {"sysid"},
    "codegen": {"sysid", "anc"},
    "report": {"sysid", "anc", "codegen"},
    "batch": {"sysid", "anc", "codegen", "report"},
    "helmet_anc": set(PACKAGES),
}

# (c) The stages of sysid in pipeline order: a module imports from its own stage and those before it.
# Each stage is a list of dotted prefixes; "sysid" alone is the package's __init__.
SYSID_STAGES = (
    ("core", ("sysid.core",)),
    ("io", ("sysid.io",)),
    ("validation", ("sysid.validation",)),
    ("estimation", ("sysid.estimation",)),
    ("identify", ("sysid.identify",)),
    ("findings", ("sysid.findings",)),
    ("refits", ("sysid.refits",)),
    ("effects", ("sysid.effects",)),
    ("verbs", ("sysid.diagnose", "sysid.refine", "sysid.simulate", "sysid.random_plant", "sysid")),
)
# The finder of old import paths: it imports nothing by name, and it is no stage of the pipeline.
STAGE_EXEMPT = {"sysid._moved"}


@dataclass(frozen=True)
class Import:
    """One import statement's dependency: ``importer`` (file ``path``, line ``line``) loads ``imported``."""

    importer: str
    path: str
    line: int
    imported: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.importer} imports {self.imported}"


def _modules(folders) -> dict[str, str]:
    """Dotted module name -> path relative to the repository, for every .py file under ``folders``."""
    found = {}
    for folder in folders:
        for path in sorted((REPO / folder).rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            parts = path.relative_to(REPO).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            found[name] = path.relative_to(REPO).as_posix()
    return found


def _moved() -> dict[str, str]:
    """``sysid._moved.MOVED`` as written in its source (old module name -> new one)."""
    tree = ast.parse((REPO / "sysid" / "_moved.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "MOVED" for t in node.targets):
            return ast.literal_eval(node.value)
    raise AssertionError("sysid/_moved.py: no MOVED dict")


MODULES = _modules(PACKAGES)
MOVED = _moved()


def _resolve(name: str) -> str | None:
    """The project module ``name`` loads: itself, its new path if it moved, else the longest enclosing module."""
    while name:
        if name in MODULES:
            return name
        if name in MOVED:
            return MOVED[name]
        name = name.rpartition(".")[0]
    return None


def _imports_of(module: str, path: str, source: str | None = None) -> list[Import]:
    """Every import of a project module by ``module`` (file ``path``, or the text ``source``), at any depth of
    the file: in functions, classes and conditionals too."""
    tree = ast.parse((REPO / path).read_text() if source is None else source, filename=path)
    package = module if path.endswith("__init__.py") else module.rpartition(".")[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                origin = ".".join(base + ([node.module] if node.module else []))
            else:
                origin = node.module
            # ``from a import b`` loads the module a.b when there is one, else a (b a name defined in it).
            targets = [f"{origin}.{alias.name}" if f"{origin}.{alias.name}" in MODULES or f"{origin}.{alias.name}" in MOVED
                       else origin for alias in node.names]
        else:
            continue
        for target in targets:
            resolved = _resolve(target) if target.split(".")[0] in PACKAGES else None
            if resolved is not None and resolved != module:
                found.append(Import(module, path, node.lineno, resolved))
    return sorted(set(found), key=lambda i: (i.path, i.line, i.imported))


IMPORTS = [i for module, path in MODULES.items() for i in _imports_of(module, path)]


def _package(module: str) -> str:
    return module.split(".")[0]


def _stage(module: str) -> int | None:
    """Index in SYSID_STAGES of a sysid module's stage (the longest matching prefix), None if it has none."""
    best, length = None, -1
    for index, (_, prefixes) in enumerate(SYSID_STAGES):
        for prefix in prefixes:
            matches = module == prefix or (prefix != "sysid" and module.startswith(prefix + "."))
            if matches and len(prefix) > length:
                best, length = index, len(prefix)
    return best


def _cycles() -> list[tuple[list[Import], list[Import]]]:
    """Per strongly connected group of modules (Tarjan): its shortest cycle through its first module (the
    imports in order) and every import inside the group."""
    edges: dict[str, dict[str, Import]] = {}
    for i in IMPORTS:
        edges.setdefault(i.importer, {}).setdefault(i.imported, i)
    index, low, stack, on_stack, groups = {}, {}, [], set(), []

    def connect(v):
        # Iterative Tarjan: a recursive one runs out of stack on long import chains.
        work = [(v, iter(sorted(edges.get(v, {}))))]
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        while work:
            node, successors = work[-1]
            for w in successors:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(edges.get(w, {})))))
                    break
                if w in on_stack:
                    low[node] = min(low[node], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    group = set()
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        group.add(w)
                        if w == node:
                            break
                    if len(group) > 1:
                        groups.append(group)

    for v in sorted(MODULES):
        if v not in index:
            connect(v)
    cycles = []
    for group in groups:
        # The shortest cycle through the group's first module, by breadth-first search inside the group.
        start = min(group)
        previous = {start: None}
        frontier, closing = [start], None
        while frontier and closing is None:
            following = []
            for v in frontier:
                for w in sorted(edges.get(v, {})):
                    if w == start:
                        closing = v
                        break
                    if w in group and w not in previous:
                        previous[w] = v
                        following.append(w)
                if closing is not None:
                    break
            frontier = following
        path = [closing]
        while previous[path[-1]] is not None:
            path.append(previous[path[-1]])
        path.reverse()
        inside = sorted((i for i in IMPORTS if i.importer in group and i.imported in group),
                        key=lambda i: (i.path, i.line, i.imported))
        cycles.append(([edges[a][b] for a, b in zip(path, path[1:] + [start])], inside))
    return sorted(cycles, key=lambda c: c[0][0].importer)


def test_imports_are_read_at_every_depth_relative_or_absolute_old_paths_as_new():
    source = """
import numpy as np
from . import wav
from .recordings import Recording
from ..core import lti, thresholds
import sysid.estimation.spectra as spectra
from sysid import identify, Model


def later():
    from ..estimation.output_error import block_data
    if True:
        import sysid.lti
"""
    found = {(i.line, i.imported) for i in _imports_of("sysid.io.channels", "sysid/io/channels.py", source)}
    assert found == {(3, "sysid.io.wav"), (4, "sysid.io.recordings"), (5, "sysid.core.lti"), (5, "sysid.core.thresholds"),
                     (6, "sysid.estimation.spectra"), (7, "sysid.identify"), (7, "sysid"),
                     (11, "sysid.estimation.output_error"), (13, "sysid.core.lti")}
    # A package's __init__ imports relative to itself.
    init = _imports_of("sysid.io", "sysid/io/__init__.py", "from .wav import read_layout\nfrom .. import simulate\n")
    assert {i.imported for i in init} == {"sysid.io.wav", "sysid.simulate"}
    assert "helmet_anc.commands" in MODULES and ("helmet_anc.cli", "sysid.io.recordings") in {
        (i.importer, i.imported) for i in IMPORTS}


def test_no_import_cycles():
    cycles = _cycles()
    message = "\n\n".join(
        f"  {len({i.importer for i in inside})} modules in a circle, e.g. "
        + " -> ".join([cycle[0].importer] + [i.imported for i in cycle]) + "; every import inside it:\n"
        + "\n".join(f"    {i}" for i in inside)
        for cycle, inside in cycles)
    assert not cycles, f"{len(cycles)} import cycle(s) among the project's modules:\n{message}"


def test_packages_import_only_downwards():
    upward = [i for i in IMPORTS if _package(i.imported) != _package(i.importer)
              and _package(i.imported) not in MAY_IMPORT[_package(i.importer)]]
    message = "\n".join(f"  {i} ({_package(i.importer)} may import only "
                        f"{', '.join(sorted(MAY_IMPORT[_package(i.importer)])) or 'itself'})" for i in upward)
    assert not upward, f"{len(upward)} import(s) of a higher package:\n{message}"


def test_every_sysid_module_has_a_stage():
    placeless = [f"  {path}: {module}" for module, path in MODULES.items()
                 if _package(module) == "sysid" and module not in STAGE_EXEMPT and _stage(module) is None]
    assert not placeless, "sysid modules in no stage of SYSID_STAGES:\n" + "\n".join(placeless)


def test_sysid_stages_import_only_downwards():
    upward = [i for i in IMPORTS if _package(i.importer) == "sysid" and _package(i.imported) == "sysid"
              and i.importer not in STAGE_EXEMPT and i.imported not in STAGE_EXEMPT
              and _stage(i.importer) is not None and _stage(i.imported) is not None
              and _stage(i.imported) > _stage(i.importer)]
    message = "\n".join(f"  {i} (stage {SYSID_STAGES[_stage(i.importer)][0]} imports the later stage "
                        f"{SYSID_STAGES[_stage(i.imported)][0]})" for i in upward)
    assert not upward, (f"{len(upward)} import(s) of a later stage of sysid (order: "
                        f"{' < '.join(name for name, _ in SYSID_STAGES)}):\n{message}")


def test_no_module_is_over_the_size_limit():
    sizes = {path: len((REPO / path).read_text().splitlines()) for path in _modules(SIZED_FOLDERS).values()}
    large = sorted((path, lines) for path, lines in sizes.items() if lines > MAX_LINES)
    message = "\n".join(f"  {path}: {lines} lines" for path, lines in large)
    assert not large, f"{len(large)} module(s) over {MAX_LINES} lines:\n{message}"


# Imports every old path in a fresh interpreter (a path imported before warns no more) and reports, per
# path, what is wrong: no DeprecationWarning, an import error, or a public name that is not the new path's.
_OLD_PATHS_SCRIPT = r"""
import importlib, json, sys, warnings
import sysid
from sysid._moved import MOVED

problems = []
for old, new in MOVED.items():
    if old in sys.modules:
        problems.append(f"{old}: imported before it was asked for")
        continue
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            module = importlib.import_module(old)
        except Exception as exc:
            problems.append(f"{old}: does not import ({type(exc).__name__}: {exc})")
            continue
    expected = f"{old} moved to {new}"
    if not any(issubclass(w.category, DeprecationWarning) and str(w.message).startswith(expected) for w in caught):
        problems.append(f"{old}: no DeprecationWarning '{expected}; ...'")
    target = importlib.import_module(new)
    names = getattr(target, "__all__", None) or [n for n in vars(target) if not n.startswith("_")]
    for name in names:
        try:
            same = getattr(module, name) is getattr(target, name)
        except AttributeError as exc:
            problems.append(f"{old}.{name}: {exc}")
            continue
        if not same:
            problems.append(f"{old}.{name} is not {new}.{name}")
print(json.dumps(problems))
"""


def test_old_import_paths_still_import_with_a_deprecation_warning():
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    run = subprocess.run([sys.executable, "-c", _OLD_PATHS_SCRIPT], capture_output=True, text=True, cwd=REPO, env=env,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    problems = json.loads(run.stdout.strip().splitlines()[-1])
    assert MOVED, "sysid/_moved.py: MOVED is empty"
    assert not problems, f"{len(problems)} problem(s) with the old import paths of sysid/_moved.py:\n" + "\n".join(
        f"  {p}" for p in problems)


@pytest.mark.parametrize("module, stage", [("sysid.core.lti", "core"), ("sysid.io.wav", "io"), ("sysid", "verbs"),
                                           ("sysid.identify", "identify"), ("sysid.effects.delay", "effects"),
                                           ("sysid.random_plant", "verbs")])
def test_stages_are_found_by_the_longest_prefix(module, stage):
    assert SYSID_STAGES[_stage(module)][0] == stage
